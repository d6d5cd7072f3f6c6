"""Shared checks that an accelerated DETP variant equals plain DETP bit for bit."""

from __future__ import annotations

import numpy as np

import oclgi

# Photon paths of the shared plain-DETP sums (the `plain` fixture, conftest.py).
DETP_PHOTONS = 20_000

# Disc radii as fractions of the scene's bounding-box diagonal: small, 1%, 10%.
RADIUS_FRACTIONS = (0.002, 0.01, 0.1)


def cornell_engine(scenes_dir) -> oclgi.Engine:
    return oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml"))


def bunny_engine(scenes_dir) -> oclgi.Engine:
    """The Stanford bunny (a real, fine mesh) inside a closed box lit by an area light."""
    box_v = np.array([[x, y, z] for x in (-1, 1) for y in (-0.2, 1.8) for z in (-1, 1)], float) * 0.25
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    box_f = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    light_v = np.array([[-0.05, 0.44, -0.05], [0.05, 0.44, -0.05], [0.05, 0.44, 0.05], [-0.05, 0.44, 0.05]])
    light_f = np.array([[0, 1, 2], [0, 2, 3]])  # normal -y: faces down
    return oclgi.Engine(oclgi.load_dict({
        "mesh": [
            {"path": str(scenes_dir / "stanford-bunny" / "bun_zipper.ply"), "albedo": [0.7, 0.7, 0.7]},
            {"vertices": box_v, "faces": box_f, "albedo": [0.6, 0.6, 0.6]},
            {"vertices": light_v, "faces": light_f, "albedo": [0, 0, 0], "emission": [20, 20, 20]},
        ],
        "camera": {"position": [0, 0.1, 0.24], "look_at": [0, 0.1, 0], "fov": 60, "width": 32, "height": 32},
        "photons": {"count": 20000, "seed": 5, "max_depth": 8},
    }))


def surface_points(engine: oclgi.Engine, n: int, rng) -> oclgi.QueryPoints:
    """n random points on the scene's triangles (area-weighted), with their normals."""
    scene = engine.scene
    areas = scene.triangle_areas()
    tri = rng.choice(len(areas), size=n, p=areas / areas.sum())
    b = rng.dirichlet([1, 1, 1], n)
    v = scene.vertices[scene.faces[tri]]
    p = np.einsum("rk,rkc->rc", b, v)
    nrm = scene.triangle_normals()[tri] * np.where(rng.random(n) < 0.5, 1.0, -1.0)[:, None]
    return oclgi.query_points(p, nrm)


def assert_same_as_plain(engine, points, method, radius, photons=20_000, **options):
    """Accelerated accumulators identical to plain DETP's; returns both estimates."""
    plain = engine.irradiance(points, method="detp", radius=radius, photons=photons)
    fast = engine.irradiance(points, method=method, radius=radius, photons=photons, **options)
    assert plain.accumulators.any(), "the test must select some segments"
    diff = np.nonzero((plain.accumulators != fast.accumulators).any(axis=1))[0]
    assert len(diff) == 0, (
        f"{method} {options} radius {radius}: {len(diff)} of {len(points)} points differ from plain DETP "
        f"(first {diff[:5].tolist()})"
    )
    return plain, fast


def check_same(ref, got, what):
    """Accumulators ``got`` (an array or an Estimate) identical to plain DETP's ``ref``."""
    got = getattr(got, "accumulators", got)
    diff = np.nonzero((ref != got).any(axis=1))[0]
    assert len(diff) == 0, f"{what}: {len(diff)} of {len(ref)} points differ from plain DETP (first {diff[:5].tolist()})"
