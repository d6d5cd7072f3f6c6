"""Counted cost of an update: n_Rec / n_R grows like f^2 (García 2007).

f = r_D / r_0, the moving object's radius over the scene's. A path is
re-traced when one of its segments hit the object at its old pose or meets
it at its new one, so the recomputed segments scale with the object's
cross-section: n_Rec ~ n_R f^2. Measured on exact counts (the segments an
update removes), for f from 0.05 to 0.4, with the model's assumption made
true: the light field is uniform (the room's walls all emit, a furnace), so
the power reaching a ball is proportional to its area. The ball leaves the
room, so n_Rec counts exactly the paths that met it.
"""

import numpy as np
import trimesh
from analytic_scenes import box_mesh, translation

import oclgi

R0 = np.sqrt(3.0)  # the room [-1, 1]^3: its bounding sphere's radius


def _engine(f):
    room_v, room_f = box_mesh((-1, -1, -1), (1, 1, 1), inward=True)  # the walls emit into the room
    ball = trimesh.creation.icosphere(subdivisions=3)
    return oclgi.Engine(oclgi.load_dict({
        "mesh": [
            {"vertices": room_v, "faces": room_f, "albedo": [0.5, 0.5, 0.5], "emission": [1, 1, 1]},
            {"vertices": ball.vertices * f * R0, "faces": ball.faces, "movable": True, "name": "ball",
             "albedo": [0.5, 0.5, 0.5]},
        ],
        "photons": {"count": 40_000, "seed": 4, "max_depth": 12},
    }))


def test_recomputed_segments_grow_like_f_squared():
    fs = np.array([0.05, 0.1, 0.2, 0.3, 0.4])
    ratios = []
    for f in fs:
        session = oclgi.Session(_engine(f), np.array([[0, -0.99, 0, 0, 1, 0]]), radius=0.05)
        n_r = int(session.segments()[1].sum())
        stats = session.move("ball", translation(0, 0, 30))  # out of the room
        ratios.append(stats.segments_removed / n_r)
    ratios = np.array(ratios)
    k = ratios / fs**2
    # n_Rec / n_R = c f^2 with one c across the range, within 30%
    assert np.all(np.abs(k / np.exp(np.log(k).mean()) - 1) < 0.3), (fs, ratios, k)
    slope = np.polyfit(np.log(fs), np.log(ratios), 1)[0]
    assert abs(slope - 2) < 0.3, slope
