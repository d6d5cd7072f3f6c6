"""A camera session's view in two layers: static points and dynamic points.

The visible point of a pixel is either on static geometry or on a movable
object. The thesis keeps the two apart (DESIGN.md section 4): points on
static surfaces are updated incrementally with the changed segments, like
any fixed sensor; points on a moving object are recomputed against every
stored segment after each move ("dynamic points").

So the view keeps, per pixel:

- the **static layer**: the first hit among the static objects only, found
  once. Its points never change, so the estimator built over them (and any
  index over their discs) lives as long as the session, and every static
  point, seen or hidden behind a moving object, has exact up-to-date sums:
  when an object uncovers a pixel, its sums are already there;
- the **composite**: the first hit among all objects, as a fresh render
  sees it. After a move only pixels whose ray can meet a movable object's
  world box are traced again: the box's eight corners are projected and the
  bounding rectangle taken, with a margin of ``MARGIN`` pixels for float
  rounding (a ray through a pixel centre outside it cannot enter the box,
  the projection of a box being the convex hull of its corners'). Pixels
  whose composite hit is on a movable object are the dynamic points.

A composite point off the movable objects is bit for bit the static layer's
point: the same ray meets the same triangle with the same arithmetic,
whatever else the traversal visited (kernels/bvh.h). Hence the composite
equals a full camera pass at the current pose, which the session tests
check.

The rectangle's rays need not walk the static geometry again: a ray's walk
visits the instances in index order, each against the best hit so far, and
the static objects come before the movable ones, so the full pass's best
hit after the static objects is the static layer's first hit. The view
keeps those hits (a float4 per pixel on the device) and re-traces the
rectangle through the movable objects alone, from them
(kernels/camera.cl ``first_in``): the same hits, bit for bit, at the cost
of the movable objects' walk (Sponza, 13,560 pixels: 5.9 -> 3.3 ms a move).

With mirrors, glass or highlights in the scene a camera ray goes on past
its first surface (kernels/camera.cl), so a pixel far from a moving
object's projection can see it (in a mirror), and a pixel can see a static
surface through a moving glass: every pixel is re-traced after a move, and
the dynamic points are those whose composite point (position, normal or
weight) differs from the static layer's, or lies on a movable object.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from ..accel.boxes import box_corners
from ..cl.layout import Instance
from ..queries import QueryPoints
from ..scene.instance_boxes import instance_buffer, instance_buffer_bytes

MARGIN = 2  # pixels around a projected box (float rounding of the rays)


class DynamicView:
    """Static layer, composite view and dynamic pixels of one camera."""

    def __init__(self, engine, camera=None):
        self.engine = engine
        self.cam = engine.view_camera(camera)
        scene, compiled = engine.scene, engine.compiled
        self.movable = [k for k, o in enumerate(scene.objects) if o.movable]
        static = [k for k, o in enumerate(scene.objects) if not o.movable]
        records = compiled.instances_host[static] if static else np.zeros(1, Instance)
        self.static_instances = (instance_buffer(engine.ctx, np.ascontiguousarray(records)), len(static))
        ranges = scene.object_ranges()
        self.movable_ranges = ranges[self.movable] if self.movable else np.zeros((0, 2), np.int64)
        full = (0, 0, self.cam.width, self.cam.height)
        # a camera ray that can go on past its first surface (module doc)
        self.through = any(m.kind != "diffuse" for m in scene.materials)
        # The rectangle's rays go on from the static layer's first hits
        # through the movable objects' records alone (module doc): a ray
        # that stops at its first surface, every static object before
        # every movable one. The records are brought up to date each move.
        self.movable_instances = self.first_hits = None
        if self.movable and not self.through and (not static or max(static) < min(self.movable)):
            self.movable_instances = instance_buffer(engine.ctx, self._movable_records(), cl.mem_flags.READ_WRITE)
            self.first_hits = cl.Buffer(engine.ctx, cl.mem_flags.READ_WRITE, 16 * self.cam.width * self.cam.height)
        self._lift = None
        self.static = engine.view_points(self.cam, full, self.static_instances, lift=self.lift(),
                                         first_out=self.first_hits)
        self.points = engine.view_points(self.cam, full, lift=self.lift())
        self.dynamic = np.nonzero(self.is_dynamic(np.arange(len(self.points)), self.points))[0]

    def _movable_records(self) -> np.ndarray:
        return np.ascontiguousarray(self.engine.compiled.instances_host[self.movable])

    def lift(self) -> float:
        """The scene's disc radius, which lifts points off tilted shading
        normals (Engine.view_points): read once per scene, as a move does
        not change it and its bounds pass over every vertex (milliseconds
        per frame on a large scene)."""
        scene = self.engine.scene
        if self._lift is None or self._lift[0] is not scene:
            self._lift = (scene, scene.radius)
        return self._lift[1]

    def is_dynamic(self, pix: np.ndarray, sub) -> np.ndarray:
        """Which of the pixels ``pix``, whose composite points are ``sub``,
        hold dynamic points (module doc)."""
        dyn = self.on_movable(sub.tri)
        if self.through:
            s = self.static
            for a, b in ((s.positions[pix], sub.positions), (s.normals[pix], sub.normals),
                         (s.weights4()[pix], sub.weights4())):
                dyn |= (a.view(np.int32) != b.view(np.int32)).any(axis=1)
        return dyn

    def on_movable(self, tri: np.ndarray) -> np.ndarray:
        hit = np.zeros(len(tri), bool)
        for a, b in self.movable_ranges:
            hit |= (tri >= a) & (tri < b)
        return hit

    def rectangle(self):
        """(x0, y0, w, h): pixels that may see a movable object (module doc)."""
        cam = self.cam
        if self.through:
            return 0, 0, cam.width, cam.height
        eye, fwd, right, up = cam.frame()
        inst = self.engine.compiled.instances_host[self.movable]
        if not len(inst):
            return 0, 0, 0, 0
        v = box_corners(inst["lo"], inst["hi"]).reshape(-1, 3) - eye  # every box's 8 corners
        depth = v @ fwd
        if (depth <= 1e-9 * np.maximum(np.abs(v).reshape(len(inst), -1).max(axis=1), 1.0).repeat(8)).any():
            return 0, 0, cam.width, cam.height  # a box reaches behind the eye: every pixel
        xs = ((v @ right) / (right @ right) / depth + 1.0) * cam.width / 2.0 - 0.5
        ys = (1.0 - (v @ up) / (up @ up) / depth) * cam.height / 2.0 - 0.5
        x0 = int(np.clip(np.floor(xs.min()) - MARGIN, 0, cam.width))
        x1 = int(np.clip(np.ceil(xs.max()) + MARGIN + 1, 0, cam.width))
        y0 = int(np.clip(np.floor(ys.min()) - MARGIN, 0, cam.height))
        y1 = int(np.clip(np.ceil(ys.max()) + MARGIN + 1, 0, cam.height))
        return x0, y0, max(x1 - x0, 0), max(y1 - y0, 0)

    def update(self):
        """After a move: re-trace the rectangle; returns (changed pixels, new
        dynamic pixels). Changed pixels hold a new composite point."""
        x0, y0, rw, rh = rect = self.rectangle()
        w = self.cam.width
        ys, xs = np.divmod(np.arange(rw * rh), max(rw, 1))
        pix = (y0 + ys) * w + x0 + xs
        if self.movable_instances is not None:
            # the event holds the host array; kept, as pyopencl waits for a dropped one
            self._records_copy = cl.enqueue_copy(self.engine.queue, self.movable_instances,
                                            instance_buffer_bytes(self._movable_records()), is_blocking=False)
            sub = self.engine.view_points(self.cam, rect, (self.movable_instances, len(self.movable)),
                                          lift=self.lift(), first_in=self.first_hits)
        else:
            sub = self.engine.view_points(self.cam, rect, lift=self.lift())
        dyn_new = pix[self.is_dynamic(pix, sub)]
        mark = np.zeros(len(self.points), bool)  # the union, sorted (np.union1d sorts: slower)
        mark[self.dynamic] = True
        mark[dyn_new] = True
        changed = np.flatnonzero(mark)
        # composite: the static point where the last move left a dynamic
        # one (the new ones are all inside the rectangle), then the
        # rectangle's re-traced points, written as an image's rows (slices:
        # a quarter of fancy indexing's time)
        p, s, old = self.points, self.static, self.dynamic
        pairs = [(p.positions, s.positions, sub.positions), (p.normals, s.normals, sub.normals),
                 (p.barys, s.barys, sub.barys)]
        if p.weights is not None:
            pairs.append((p.weights, s.weights4(), sub.weights4()))
        for dst, static, new in pairs:  # the view's own arrays (view_points'): C-contiguous, reshaped as views
            dst[old] = static[old]
            k = dst.shape[1]
            dst.reshape(self.cam.height, w, k)[y0:y0 + rh, x0:x0 + rw] = new.reshape(rh, rw, k)
        self.dynamic = dyn_new
        return changed, dyn_new

    def subset(self, index) -> QueryPoints:
        return self.points.subset(index)
