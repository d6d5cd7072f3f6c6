"""Image error at equal time with one and with four samples per pixel:
oclgi ``--spp 1`` and ``--spp 4`` against Mitsuba 3's path tracer, on the
Cornell box, in one run.

One sample per pixel looks at the pixel's centre: at a silhouette or a
corner the pixel shows one side, where a reference (Mitsuba's box filter)
shows the mean of both, an error no photon count removes. Four samples
integrate the pixel, at the cost of four query points per pixel from the
same photons (far less than four renders: bench/HISTORY.md "Samples per
pixel"), so at equal time they have fewer photons each: less aliasing at
the edges, more noise inside. This bench measures both, at equal time.

The reference: Mitsuba at ``--ref-spp`` samples per pixel, two seeds, their
mean (its own error from the halves' difference is reported). The error:
relative RMS of luminance against it, over three sets of pixels: all
covered pixels, the edge pixels (oclgi.study.image_compare.discontinuities
on the pixel-centre points: a change of surface, normal, depth or material
between 4-neighbours) and the interior (covered pixels more than one pixel
from an edge). Times are wall-clock seconds of the whole render (camera,
trace, estimate / Mitsuba's render) after a warm-up of each; the photon
counts and Mitsuba's spp are budgets swept one after another in this
process, and the equal-time comparison interpolates each curve in log-log.

Writes ``bench/results/spp_equal_time.md`` and ``spp_equal_time.png`` and
keeps the reference under ``--out`` for the next run.

Usage: ``.venv/bin/python bench/spp_equal_time.py [--size 96] [--ref-spp 4096]
[--variant llvm_ad_rgb]`` (about 6 minutes on 2 cores; ``--quick``: 48 x 48,
a smoke run). Needs ``pip install 'oclgi[mitsuba]'`` and, for the llvm
variant, an LLVM of at least 16 (Debian 12: ``apt-get install libllvm19``).
"""

from __future__ import annotations

import numpy as np

from common import RESULTS, ROOT, engine as make_engine, machine_line, timed, write
from oclgi.study.image_compare import dilate, discontinuities
from reference_images import add_row, mitsuba_sweep, parse_args, plot, reference_pair, rel_rms

SCENE = ROOT / "scenes" / "cornell_box.toml"
REGIONS = ("all", "edges", "interior")


def at_time(points, t: float) -> float:
    """The error a curve of (seconds, error) points reaches at time t, interpolated in log-log (NaN outside)."""
    ts, es = (np.log(np.array(v)) for v in zip(*sorted(points)))
    if not ts[0] <= np.log(t) <= ts[-1]:
        return float("nan")
    return float(np.exp(np.interp(np.log(t), ts, es)))


def main():
    args = parse_args(__doc__, "spp_equal_time", 4096, "1e5,2.5e5,5e5,1e6,2e6,4e6", "4,16,64,256",
                      (256, "1e5,4e5", "4,16"))
    s = args.size
    engine = make_engine(SCENE)
    ref_a, ref_b, ref_seconds = reference_pair(engine, s, args.ref_spp, args.variant, args.out)
    ref = 0.5 * (ref_a + ref_b)
    points = engine.camera_points(width=s, height=s)
    covered = (points.tri >= 0).reshape(s, s)
    edges = discontinuities(points, engine.scene) & covered
    regions = {"all": covered, "edges": edges, "interior": covered & ~dilate(edges, 1)}
    ref_error = {k: rel_rms(ref_a, ref_b, m) / 2.0 for k, m in regions.items()}  # the mean's: 1/sqrt(2) of a half's

    def error(img):
        return {k: rel_rms(img, ref, m) for k, m in regions.items()}

    rows = []  # (renderer, budget, seconds, {region: error})
    for spp in (1, 4):
        engine.render(width=s, height=s, photons=args.photons[0], spp=spp)  # warm-up: kernel builds
    for n in args.photons:  # alternating, so that a change in the machine's load touches both alike
        for spp in (1, 4):
            t, r = timed(engine.render, width=s, height=s, photons=n, spp=spp)
            add_row(rows, f"oclgi --spp {spp}", f"{n:,} photons", t, error(r.radiance))
    mitsuba_sweep(rows, engine, s, args.spp, args.variant, error)

    names = list(dict.fromkeys(r[0] for r in rows))
    curves = {(name, k): [(t, e[k]) for a, _, t, e in rows if a == name] for name in names for k in REGIONS}
    # equal time: at each --spp 4 render's time, every renderer's error there
    four = [r for r in rows if r[0] == "oclgi --spp 4"]
    equal = [(t, k, {name: at_time(curves[name, k], t) for name in names}) for _, _, t, _ in four for k in REGIONS]

    lines = [
        "# Image error at equal time, one and four samples per pixel (Cornell box)", "",
        f"{s} x {s} pixels: {int(covered.sum())} covered, {int(edges.sum())} on edges, "
        f"{int(regions['interior'].sum())} interior; `detp_disc_index`, the scene's radius; reference: Mitsuba 3 "
        f"`{args.variant}` path tracer, 2 x {args.ref_spp:,} spp ({ref_seconds:.0f} s), its own relative RMS "
        "error about " + ", ".join(f"{ref_error[k]:.4f} ({k})" for k in REGIONS) + ". Wall-clock seconds of "
        "the whole render.", "",
        machine_line(engine.queue.device), "",
        "| renderer | budget | seconds | all | edges | interior |", "|---|---|---:|---:|---:|---:|",
        *[f"| {a} | {b} | {t:.2f} | " + " | ".join(f"{e[k]:.4f}" for k in REGIONS) + " |" for a, b, t, e in rows], "",
        "Equal time (each curve interpolated in log-log at the time of each `--spp 4` render; blank: outside "
        "that curve's range):", "",
        "| seconds | pixels | " + " | ".join(names) + " |",
        "|---:|---|" + "---:|" * len(names),
        *[f"| {t:.2f} | {k} | " + " | ".join("" if np.isnan(v[n]) else f"{v[n]:.4f}" for n in names) + " |"
          for t, k, v in equal], "",
    ]
    write("spp_equal_time.md", "\n".join(lines))
    plot(RESULTS / "spp_equal_time.png", [(f"{k} pixels", {name: curves[name, k] for name in names}, ref_error[k])
                                          for k in REGIONS], "relative RMS error", (10, 3.6), 110)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
