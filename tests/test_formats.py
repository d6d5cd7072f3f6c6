"""Mesh and scene files read right or refused in plain words.

Degenerate triangles are judged each by its own shape (a huge ground plane
does not make a room's light "degenerate"); glTF with external buffers,
PLY/OFF whose counts lie, zip members that inflate past the limit, deeply
nested TOML and numbers beyond float32 are read or refused with one
OclgiError naming the file and the problem.
"""

import warnings
import zipfile

import numpy as np
import pytest
import trimesh

from oclgi.errors import OclgiError
from oclgi.scene.degenerate import degenerate_triangles
from oclgi.scene.description import load_dict, load_file
from oclgi.scene.mesh import load_mesh
from oclgi.scene.scene import OclgiWarning

FLOOR = {"vertices": [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], "faces": [[0, 2, 1], [0, 3, 2]]}
# 0.4 m x 0.4 m: 0.16 m^2 in two triangles
LIGHT = {"vertices": [[-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2], [-0.2, 1, 0.2]],
         "faces": [[0, 1, 2], [0, 2, 3]], "emission": [5, 5, 5]}
H = 1e5  # half of a 200 km ground plane
GROUND = {"vertices": [[-H, -0.1, -H], [H, -0.1, -H], [H, -0.1, H], [-H, -0.1, H]], "faces": [[0, 2, 1], [0, 3, 2]]}


# -- degenerate triangles ---------------------------------------------------------------

def test_huge_ground_plane_keeps_the_light():
    with warnings.catch_warnings():
        warnings.simplefilter("error", OclgiWarning)  # nothing is dropped
        scene = load_dict({"mesh": [FLOOR, LIGHT, GROUND]})
    assert scene.n_triangles == 6
    assert scene.has_emitter()
    assert np.isclose(scene.triangle_areas()[scene.tri_material == 1].sum(), 0.16)


def test_slivers_and_zero_area_triangles_still_dropped_beside_a_huge_plane():
    bad = {"vertices": [[0, 0.5, 0], [1, 0.5, 0], [2, 0.5 + 1e-9, 0], [0, 0.5, 0]],
           "faces": [[0, 1, 2], [0, 3, 1], [0, 0, 1]]}  # a sliver, two vertices equal, one index twice
    with pytest.warns(OclgiWarning, match=r"dropped 3 degenerate triangles"):
        scene = load_dict({"mesh": [FLOOR, LIGHT, GROUND, bad]})
    assert scene.n_triangles == 6


def test_degeneracy_is_relative_to_each_triangle():
    # the same shape at any size is kept or dropped alike
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    sliver = np.array([[0, 0, 0], [1, 0, 0], [2, 1e-8, 0]], float)
    faces = np.array([[0, 1, 2]])
    for s in (1e-15, 1e-3, 1.0, 1e6, 1e15):
        assert not degenerate_triangles(tri * s, faces).any(), s
        assert degenerate_triangles(sliver * s, faces).all(), s


def test_degeneracy_as_float32_sees_it():
    # distinct in float64, one point in float32: the device sees no triangle
    v = np.array([[1.0, 1.0, 1.0], [1.0 + 1e-9, 1.0, 1.0], [1.0, 1.0 + 1e-9, 1.0]])
    assert degenerate_triangles(v, np.array([[0, 1, 2]])).all()
    # so tiny that the float32 normal flushes to zero
    assert degenerate_triangles(v * 1e-25 - 1e-25, np.array([[0, 1, 2]])).all()
