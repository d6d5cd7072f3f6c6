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

import numpy as np

import oclgi
from common import RESULTS, ROOT, engine as make_engine, machine_line, timed, write
from reference_images import add_row, mitsuba_sweep, parse_args, plot, reference_pair, rel_rms

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
    args = parse_args(__doc__, "caustic_equal_time", 8192, "2.5e5,5e5,1e6,2e6,4e6,8e6", "16,64,256,1024,4096",
                      (1024, "2.5e5,1e6", "16,128"), caustic_radius=0.35, oclgi_spp=(16, (
                          "oclgi's samples per pixel: the caustic's sharp edges need the pixel integrated, as "
                          "Mitsuba's box filter does (4 samples leave 25%% RMS of aliasing at 96 x 96)")))
    s = args.size
    engine = make_engine(SCENE)
    ref_a, ref_b, ref_seconds = reference_pair(engine, s, args.ref_spp, args.variant, args.out)
    ref = 0.5 * (ref_a + ref_b)
    region = caustic_region(engine, engine.camera_points(width=s, height=s), args.caustic_radius)
    # the reference's own error: half the halves' difference is one half's; the mean has 1/sqrt(2) of it
    ref_error = rel_rms(ref_a, ref_b, region) / np.sqrt(2.0) / np.sqrt(2.0)

    rows = []
    engine.render(width=s, height=s, photons=args.photons[0], spp=args.oclgi_spp)  # warm-up: kernel builds
    for method in ("detp_disc_index", "photon_map"):
        for n in args.photons:
            t, r = timed(engine.render, width=s, height=s, photons=n, spp=args.oclgi_spp, method=method)
            add_row(rows, f"oclgi {method}", f"{n:,} photons", t, rel_rms(r.radiance, ref, region))
        args.out.mkdir(parents=True, exist_ok=True)
        oclgi.save_render(r, args.out / f"{method}.exr")
    mitsuba_sweep(rows, engine, s, args.spp, args.variant, lambda img: rel_rms(img, ref, region))

    lines = [
        "# Equal-time error in the caustic of CornellBox-Sphere", "",
        f"{s} x {s} pixels, {int(region.sum())} pixels in the caustic region (floor within "
        f"{args.caustic_radius} of the glass sphere's foot); reference: Mitsuba 3 `{args.variant}` path tracer, "
        f"2 x {args.ref_spp:,} spp ({ref_seconds:.0f} s), its own relative RMS error about {ref_error:.4f}. "
        f"oclgi renders with {args.oclgi_spp} samples per pixel (camera paths through the mirror and the glass; "
        "the caustic's edges need the pixel integrated as Mitsuba's box filter does), DETP's "
        "radius from the scene file (0.02), Photon Maps k = 50. Wall-clock seconds of the whole render.", "",
        machine_line(engine.queue.device), "",
        "| renderer | budget | seconds | relative RMS error |", "|---|---|---:|---:|",
        *[f"| {a} | {b} | {t:.2f} | {e:.4f} |" for a, b, t, e in rows], "",
    ]
    write("caustic_equal_time.md", "\n".join(lines))
    curves = {name: [(t, e) for a, _, t, e in rows if a == name] for name in dict.fromkeys(r[0] for r in rows)}
    plot(RESULTS / "caustic_equal_time.png", [("", curves, ref_error)], "relative RMS error in the caustic",
         (6, 4), 120)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
