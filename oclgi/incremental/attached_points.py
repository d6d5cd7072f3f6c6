"""Query points on movable objects follow them (a session over given points).

A session's query points are fixed in the world, but a point on a movable
object (its ``tri``, as tessellated or vertex points carry it, is one of the
object's triangles) is a point of the object: when the object moves, so
does the point, by the object's matrix (its normal by the inverse
transpose). Such points play the part a camera session's dynamic points
play (oclgi/incremental/dynamic_view.py), with the same interface:

- the **static layer**: the points as given, the attached ones disabled (a
  zero normal). The session's estimator keeps the others' sums for good,
  updated incrementally with the changed segments;
- the **composite**: the points where they are now: static points as given,
  attached points where their object has taken them;
- the **dynamic points**: the attached ones, recomputed from the whole store
  after each move (their neighbourhood moved with them).

Back at a pose an object had when the session opened, its points are the
given ones bit for bit (the relative transform is not applied when it is
the identity).
"""

from __future__ import annotations

import numpy as np

from ..queries import QueryPoints
from ..scene.pose import as_transform


class AttachedPoints:
    """Static layer, composite and dynamic (attached) points of given query points."""

    cam = None  # not a camera's view
    through = False

    def __init__(self, engine, points: QueryPoints, as_loaded: bool = False):
        """``as_loaded``: the points are where the objects were loaded (a
        tessellation of the scene file's geometry); else where the engine
        has the objects now (a session's points as given when it opens)."""
        self.engine, self.given, self.points = engine, points, points.copy()
        scene = engine.scene
        tri = points.tri
        self.groups = []  # (object, point ids, the object's pose when the session opened)
        for obj, (a, b) in enumerate(scene.object_ranges()):
            ids = np.nonzero((tri >= a) & (tri < b))[0]
            if scene.objects[obj].movable and len(ids):
                self.groups.append((obj, ids, np.eye(4) if as_loaded else engine.compiled.pose.matrix(obj)))
        self.dynamic = (np.concatenate([g[1] for g in self.groups]) if self.groups
                        else np.zeros(0, np.int64))
        self.dynamic.sort()
        # the static layer: an attached point's sums come from the dynamic
        # estimator, so its static copy has a zero normal (a disc that never
        # counts, and that no index holds: oclgi/accel/boxes.py active_discs)
        self.static = points.copy()
        self.static.normals[self.dynamic] = 0.0

    def update(self):
        """After a move: every attached point placed by its object's current
        pose; returns (changed points, dynamic points): both the attached ones."""
        pose = self.engine.compiled.pose
        s, p = self.given, self.points
        for obj, ids, pose0 in self.groups:
            m = as_transform(pose.matrix(obj))
            p.positions[ids] = s.positions[ids]
            p.normals[ids] = s.normals[ids]
            if not np.array_equal(m, pose0):
                rel = m @ np.linalg.inv(pose0)
                p.positions[ids, :3] = s.positions[ids, :3].astype(np.float64) @ rel[:3, :3].T + rel[:3, 3]
                n = s.normals[ids, :3].astype(np.float64) @ np.linalg.inv(rel[:3, :3])  # inverse transpose
                p.normals[ids, :3] = n / np.linalg.norm(n, axis=1)[:, None]
        return self.dynamic, self.dynamic

    def subset(self, index) -> QueryPoints:
        return self.points.subset(index)
