"""Equal-time error in the caustic of CornellBox-Sphere: oclgi (DETP with disc
indexing, Photon Maps) against Mitsuba 3's path tracer, in one run.

The caustic is the light the glass sphere focuses onto the floor: light ->
glass -> glass -> floor -> camera, a path a path tracer only finds when its
BSDF sample from the floor happens to pass through the sphere and hit the
small light (next-event estimation cannot see the light through glass).
Density estimation collects it from the photons directly.

The region: the floor pixels (visible point on the floor, seen directly)
within ``--caustic-radius`` of the point under the sphere's centre. The
reference: Mitsuba at ``--ref-spp`` samples per pixel, two seeds, their
mean (its own error is estimated from the difference of the two halves and
reported). The error: relative RMS of luminance over the region, against
the reference. Each method runs at several budgets (photons, samples per
pixel), one after another in this process; the times are wall-clock seconds
of the whole render (camera, trace, estimate / Mitsuba's render), after a
warm-up run of each (kernel builds and Mitsuba's JIT are not counted).

Writes ``bench/results/caustic_equal_time.md`` and ``caustic_equal_time.png``
(error against time, both axes logarithmic) and the images of the largest
budgets to ``--out`` (EXR), where the reference is kept for the next run.

Usage: ``.venv/bin/python bench/caustic_equal_time.py [--size 96]
[--ref-spp 8192] [--variant llvm_ad_rgb]`` (about 10 minutes on 2 cores;
``--quick``: 48 x 48, 1024 spp reference, for a smoke run). Needs
``pip install 'oclgi[mitsuba]'`` and, for the llvm variant, an LLVM of at
least 16 (Debian 12: ``apt-get install libllvm19``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import oclgi
from oclgi.study import mitsuba as mitsuba_reference
from reference_images import reference_pair, rel_rms

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
SCENE = ROOT / "scenes" / "cornell_sphere.toml"


def caustic_region(engine, points, radius: float) -> np.ndarray:
    """(H, W) bool: pixels seeing the floor directly near the glass sphere's foot."""
    scene = engine.scene
    floor = [i for i, m in enumerate(scene.materials) if m.name.endswith(":floor")]
    glass = [i for i, m in enumerate(scene.materials) if m.name.endswith(":rightSphere")]
    tri_glass = np.nonzero(np.isin(scene.tri_material, glass))[0]
    centre = scene.vertices[scene.faces[tri_glass]].reshape(-1, 3).mean(axis=0)
    tri = points.tri
    on_floor = (tri >= 0) & np.isin(scene.tri_material[np.maximum(tri, 0)], floor)
    direct = points.weights4()[:, 0] == 1.0
    xz = points.positions[:, [0, 2]].astype(np.float64)
    near = np.hypot(xz[:, 0] - centre[0], xz[:, 1] - centre[2]) < radius
    return (on_floor & direct & near).reshape(points.shape)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--ref-spp", type=int, default=8192, help="per reference image (two are rendered)")
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("--caustic-radius", type=float, default=0.35)
    ap.add_argument("--photons", default="2.5e5,5e5,1e6,2e6,4e6,8e6")
    ap.add_argument("--oclgi-spp", type=int, default=16,
                    help="oclgi's samples per pixel: the caustic's sharp edges need the pixel integrated, as "
                         "Mitsuba's box filter does (4 samples leave 25%% RMS of aliasing at 96 x 96)")
    ap.add_argument("--spp", default="16,64,256,1024,4096")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "caustic_equal_time")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.size, args.ref_spp, args.photons, args.spp = 48, 1024, "2.5e5,1e6", "16,128"
    photons = [int(float(x)) for x in args.photons.split(",")]
    spps = [int(x) for x in args.spp.split(",")]
    s = args.size
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", oclgi.OclgiWarning)  # the file's Kd on the mirror and glass
        engine = oclgi.Engine(oclgi.load_file(SCENE), progress=False)

    ref_a, ref_b, ref_seconds = reference_pair(engine, s, args.ref_spp, args.variant, args.out)
    ref = 0.5 * (ref_a + ref_b)
    points = engine.camera_points(width=s, height=s)
    region = caustic_region(engine, points, args.caustic_radius)
    # the reference's own error: half the halves' difference is one half's; the mean has 1/sqrt(2) of it
    ref_error = rel_rms(ref_a, ref_b, region) / np.sqrt(2.0) / np.sqrt(2.0)

    rows = []
    engine.render(width=s, height=s, photons=photons[0], spp=args.oclgi_spp)  # warm-up: kernel builds
    for method in ("detp_disc_index", "photon_map"):
        for n in photons:
            t = time.perf_counter()
            r = engine.render(width=s, height=s, photons=n, spp=args.oclgi_spp, method=method)
            rows.append((f"oclgi {method}", f"{n:,} photons", time.perf_counter() - t, rel_rms(r.radiance, ref, region)))
            print(*rows[-1], flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        oclgi.save_render(r, args.out / f"{method}.exr")
    mitsuba_reference.render(engine, width=s, height=s, spp=4, seed=0, variant=args.variant)  # warm-up: JIT
    for spp in spps:
        t = time.perf_counter()
        img = mitsuba_reference.render(engine, width=s, height=s, spp=spp, seed=7, variant=args.variant)
        rows.append((f"Mitsuba 3 path ({args.variant})", f"{spp:,} spp", time.perf_counter() - t,
                     rel_rms(img, ref, region)))
        print(*rows[-1], flush=True)

    dev = engine.queue.device
    lines = [
        "# Equal-time error in the caustic of CornellBox-Sphere",
        "",
        f"{s} x {s} pixels, {int(region.sum())} pixels in the caustic region (floor within "
        f"{args.caustic_radius} of the glass sphere's foot); reference: Mitsuba 3 `{args.variant}` path tracer, "
        f"2 x {args.ref_spp:,} spp ({ref_seconds:.0f} s), its own relative RMS error about {ref_error:.4f}. "
        f"oclgi renders with {args.oclgi_spp} samples per pixel (camera paths through the mirror and the glass; "
        "the caustic's edges need the pixel integrated as Mitsuba's box filter does), DETP's "
        "radius from the scene file (0.02), Photon Maps k = 50. Wall-clock seconds of the whole render.",
        "",
        f"Machine: {dev.name.strip()} ({dev.max_compute_units} compute units), {platform.processor() or platform.machine()}, "
        f"load average {os.getloadavg()[0]:.2f}.",
        "",
        "| renderer | budget | seconds | relative RMS error |",
        "|---|---|---:|---:|",
        *[f"| {a} | {b} | {t:.2f} | {e:.4f} |" for a, b, t, e in rows],
        "",
    ]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "caustic_equal_time.md").write_text("\n".join(lines))
    try:
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6, 4))
        ax = fig.subplots()
        for name in dict.fromkeys(r[0] for r in rows):
            pts = [(t, e) for a, _, t, e in rows if a == name]
            ax.loglog(*zip(*pts), "o-", label=name)
        ax.axhline(ref_error, color="grey", ls=":", label="reference's own error")
        ax.set_xlabel("seconds")
        ax.set_ylabel("relative RMS error in the caustic")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(RESULTS / "caustic_equal_time.png", dpi=120)
    except ImportError:
        pass
    print("\n".join(lines))


if __name__ == "__main__":
    main()
