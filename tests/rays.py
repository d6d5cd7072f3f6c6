"""Ray sets for the tracing tests and benchmarks (bench/test_rays.py imports
them too): incoherent rays through the scene's box, and the rays of
diffuse photon bounces off its surfaces."""

import numpy as np


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def incoherent_rays(scene, rng, n):
    """Origins uniform in the bounding box, directions uniform on the sphere."""
    lo, hi = scene.bounds()
    return rng.uniform(lo, hi, (n, 3)), unit(rng.normal(size=(n, 3)))


def bounce_rays(scene, rng, n):
    """Origins on the surface (area-uniform), lifted off a random side by
    1e-4 of the diagonal (10x the engine's ray offset, so that no
    intersector re-hits the origin's own triangle), directions
    cosine-distributed about that side's normal (normal + a uniform unit
    vector): the rays of diffuse photon bounces."""
    areas = scene.triangle_areas()
    tri = rng.choice(len(areas), n, p=areas / areas.sum())
    v = scene.vertices[scene.faces[tri]]
    su, r2 = np.sqrt(rng.random((n, 1))), rng.random((n, 1))
    p = v[:, 0] + su * (1 - r2) * (v[:, 1] - v[:, 0]) + su * r2 * (v[:, 2] - v[:, 0])
    normal = scene.triangle_normals()[tri] * rng.choice([-1.0, 1.0], (n, 1))
    p += 1e-4 * scene.diagonal * normal
    return p, unit(normal + unit(rng.normal(size=(n, 3))))


RAYS = {"incoherent": incoherent_rays, "bounce": bounce_rays}
