"""The estimator study at equal time (issue #4): Impact Count, Photon Maps and
DETP on the Cornell box and on the Stanford bunny in the Cornell box, against
a high-photon DETP reference, through ``oclgi.study``.

Writes into ``bench/results/``, per scene (``cornell``, ``bunny``):

- ``estimator_study_SCENE.md``   the study's report (every row, equal time);
- ``estimator_study_SCENE.csv``  its table;
- ``estimator_study_SCENE.json`` the table, the equal-time rows, the machine;
- ``estimator_study_SCENE_error_vs_time.png``, ``..._variance_vs_photons.png``.

Scenes. Impact Count estimates one value per triangle, so on the Cornell
box's 36 large triangles its error would be the triangles' bias alone; the
thesis applies it to meshed scenes. Both scenes therefore have the box's
walls split three times (midpoint subdivision, shared vertices, 64 triangles
each: 2,304 in all); the surfaces, and so every DETP and Photon Map
estimate, are the same as the shipped files'. The bunny (69,451 triangles,
scaled and placed as in ``scenes/cornell_bunny.toml``) is the real mesh; half
of its scene's points are on it, half uniform over the whole scene.

Configurations: ``detp_disc_index`` (equal to plain DETP bit for bit) with
the scenes' disc radius d = 0.03, ``photon_map`` with k = 50 (the k-1
estimator, the default) and ``impact``; photon counts over 1.5 decades each,
Impact Count's shifted up by half a decade because a photon costs it less.
8 seeds per count; 300 random surface points. Reference: DETP with 64
million photons (4 runs of 16 million) and d = 0.02, two thirds of the
study's: its disc-mean bias is second order in d and smaller than the
study's DETP's, its noise is reported; points where it is not known to 10%
(dim points, the bunny's underside) are left out of the statistics.
McGuire's file holds two faces of each block twice; they are dropped.

Usage: ``.venv/bin/python bench/estimator_study.py [--quick]`` (``--quick``:
counts and reference shrunk tenfold, 3 seeds, 100 points; a smoke run).
"""

from __future__ import annotations

import json
import os
import platform
import time

import numpy as np

import oclgi
from common import RESULTS, ROOT, arguments, concat, device, timed
from oclgi.io import atomic_path
from oclgi.study import Config, equal_time, random_surface_points, run_study
from oclgi.study.reference import Reference
from oclgi.study.report import write_all

RADIUS = 0.03
REF_RADIUS = 0.02
K = 50
HALF_DECADES = (1.0, 10**0.5, 10.0, 10**1.5)
SUBDIVISIONS = 3


def subdivide(v, f):
    """Split every triangle in four at its edge midpoints (shared between neighbours)."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = len(v) + inverse.reshape(3, len(f))  # the midpoints of edges ab, bc, ca
    v = np.vstack([v, 0.5 * (v[unique[:, 0]] + v[unique[:, 1]])])
    a, b, c = f.T
    ab, bc, ca = mid
    return v, np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])


def meshed_cornell_box() -> list:
    """The Cornell box's meshes, one per material, subdivided (module docstring)."""
    box = oclgi.load_file(ROOT / "scenes" / "cornell_box.toml")
    meshes = []
    # McGuire's file holds two of the blocks' faces twice (triangles 16-17 = 20-21,
    # 30-31 = 32-33): a ray hits one copy, so Impact Count would read zero on the other
    corners = np.sort(box.vertices[box.faces].reshape(len(box.faces), -1), axis=1)
    _, first = np.unique(corners, axis=0, return_index=True)
    keep = np.isin(np.arange(len(box.faces)), first)
    for m in np.unique(box.tri_material):
        faces = box.faces[(box.tri_material == m) & keep]
        used, local = np.unique(faces, return_inverse=True)
        v, f = box.vertices[used], local.reshape(faces.shape)
        for _ in range(SUBDIVISIONS):
            v, f = subdivide(v, f)
        mat = box.materials[m]
        meshes.append({"vertices": v, "faces": f, "albedo": list(mat.albedo), "emission": list(mat.emission)})
    return meshes


def scene(name: str):
    desc = {"mesh": meshed_cornell_box(), "photons": {"count": 1_000_000, "seed": 1, "max_depth": 16},
            "estimator": {"radius": RADIUS}, "name": name}
    if name == "bunny":
        desc["mesh"].append({"path": str(ROOT / "scenes" / "stanford-bunny" / "bun_zipper.ply"), "name": "bunny",
                             "albedo": [0.8, 0.8, 0.8],
                             "transform": {"scale": 4.0, "translate": [-0.5, -0.13, 0.55]}})
        desc["photons"]["max_depth"] = 12
    return oclgi.load_dict(desc)


def points(engine, n, rng):
    s = engine.scene
    if s.name != "bunny":
        return random_surface_points(s, n, rng)
    # the bunny is the last mesh: its triangles follow the box's
    n_box = sum(len(m["faces"]) for m in meshed_cornell_box())
    on_bunny = random_surface_points(s, n // 2, rng, triangles=np.arange(n_box, s.n_triangles))
    anywhere = random_surface_points(s, n - n // 2, rng)
    return concat([on_bunny, anywhere], kind="random")


def run(name: str, quick: bool) -> dict:
    scale = 0.1 if quick else 1.0
    base = [int(round(32_000 * scale * f)) for f in HALF_DECADES]
    configs = [Config("detp_disc_index", base, radius=RADIUS),
               Config("photon_map", base, k=K),
               Config("impact", [int(round(p * 10**0.5)) for p in base])]
    engine = oclgi.Engine(scene(name))
    rng = np.random.default_rng(2009)
    pts = points(engine, 100 if quick else 300, rng)
    ref = Reference("detp", photons=int(64_000_000 * scale), radius=REF_RADIUS, runs=4)
    t, result = timed(run_study, engine, configs, points=pts, seeds=3 if quick else 8, reference=ref)
    print(f"{name}: {t:.0f} s, {engine.scene.n_triangles:,} triangles")
    stem = f"estimator_study_{name}"
    write_all(result, RESULTS, stem=stem, plots=True, prefix=f"{stem}_")
    dev = device()
    out = {**result.to_json(), "triangles": engine.scene.n_triangles,
           "machine": {"device": dev.name.strip(), "platform": dev.platform.version.strip(),
                       "compute_units": dev.max_compute_units, "python": platform.python_version(),
                       "loadavg": [round(x, 2) for x in os.getloadavg()]},
           "equal_time_fit": equal_time(result, mode="fit").rows}
    with atomic_path(RESULTS / f"{stem}.json") as tmp:
        tmp.write_text(json.dumps(out, indent=1, default=float))
    print(result.to_markdown())
    return out


def main():
    args = arguments(__doc__, quick=False, scenes="cornell,bunny")
    t0 = time.perf_counter()
    for name in args.scenes.split(","):
        run(name, args.quick)
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
