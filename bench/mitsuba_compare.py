"""oclgi's Cornell box against Mitsuba 3's path tracer, at high quality.

Renders the Cornell box with oclgi (DETP with disc indexing) and with
Mitsuba (``oclgi.study.image.compare_with_mitsuba``, the study's own image
comparison), then renders Mitsuba once more with another seed to measure the
reference's own noise, and compares oclgi with the mean of both Mitsuba
images as well.

Writes ``bench/results/mitsuba_cornell_error.png`` (relative error of
luminance, blue: oclgi lower, red: higher, +-10% at full colour; grey:
within ``--edge-px`` pixels of an edge) and ``bench/results/mitsuba_cornell.md``;
the EXR images and the JSON go to ``--out`` (default ``out/mitsuba_cornell``).

Usage: ``.venv/bin/python bench/mitsuba_compare.py [--size 256] [--photons 10000000]
[--radius 0.03] [--spp 2048] [--edge-px 3]`` (about 10 minutes on 2 cores;
``--quick`` for a 64 x 64 smoke run). Needs ``pip install 'oclgi[mitsuba]'``.
"""

from __future__ import annotations

import os
import platform
import shutil

from common import RESULTS, ROOT, arguments, cpu_timed, engine as make_engine
from oclgi.io import atomic_path, read_image
from oclgi.study import image_compare, mitsuba as mitsuba_reference
from oclgi.study.image import compare_with_mitsuba


def _row(name, c: image_compare.Comparison):
    r = c.channel_ratio
    return (f"| {name} | {c.rel_mean:.4f} | {c.rel_median:.4f} | {c.rel_p95:.4f} | {c.signed_mean:+.4f} "
            f"| {r[0]:.4f} / {r[1]:.4f} / {r[2]:.4f} |")


def main():
    args = arguments(__doc__, size=256, photons=10_000_000, radius=0.03, edge_px=3,
                     spp=(2048, "per Mitsuba image (two are rendered)"), out=ROOT / "out" / "mitsuba_cornell",
                     quick=dict(size=64, photons=1_000_000, radius=0.05, spp=256, edge_px=2))

    engine = make_engine(ROOT / "scenes" / "cornell_box.toml")
    s = args.size
    wall, cpu_cmp, summary = cpu_timed(compare_with_mitsuba, engine, args.out, spp=args.spp, edge_px=args.edge_px,
                                       width=s, height=s, mitsuba_seed=0, error_scale=0.1, photons=args.photons,
                                       radius=args.radius, method="detp_disc_index")
    ocl, ref0 = (read_image(args.out / name) for name in ("oclgi.exr", "mitsuba.exr"))
    t_ref1, cpu_ref1, ref1 = cpu_timed(mitsuba_reference.render, engine, width=s, height=s, spp=args.spp, seed=1)

    mask = image_compare.edge_mask(engine.camera_points(width=s, height=s), args.edge_px, scene=engine.scene)
    vs0 = image_compare.compare(ocl, ref0, mask, scale=0.1)
    vs_mean = image_compare.compare(ocl, 0.5 * (ref0 + ref1), mask, scale=0.1)
    noise = image_compare.compare(ref1, ref0, mask, scale=0.1)

    with atomic_path(RESULTS / "mitsuba_cornell_error.png") as tmp:
        shutil.copyfile(args.out / "error.png", tmp)
    o, m = summary["oclgi"], summary["mitsuba"]
    spp = m["spp"]
    md = [
        "# Cornell box: oclgi against Mitsuba 3", "",
        f"{s} x {s} pixels; oclgi {o['method']}, {o['photons']:,} photons ({o['segments']:,} segments), "
        f"radius {o['radius']}, max_depth {o['max_depth']}; Mitsuba {m['version']} `{m['variant']}`, "
        f"`path` integrator, max_depth {m['max_depth']}, {m['sampler']} sampler, {spp} spp per image. "
        f"Pixels within {args.edge_px} of an edge left out: {vs0.compared:,} of {s * s:,} compared.", "",
        "Relative error of luminance over the compared pixels; channel ratios are mean(test) / mean(reference).", "",
        "| test against reference | mean | median | p95 | signed mean | R / G / B ratio |",
        "|---|---:|---:|---:|---:|---:|",
        _row(f"oclgi vs Mitsuba seed 0 ({spp} spp)", vs0),
        _row(f"oclgi vs mean of seeds 0 and 1 ({2 * spp} spp)", vs_mean),
        _row(f"Mitsuba seed 1 vs seed 0 (the reference's noise, {spp} spp each)", noise), "",
        "| renderer | seconds |", "|---|---:|",
        f"| oclgi (camera points, trace, estimate, shade) | {o['seconds']:.1f} |",
        f"| Mitsuba, one image of {spp} spp | {m['seconds']:.1f} (seed 1: {t_ref1:.1f}) |", "",
        f"Cores used (process CPU time / wall time; 2 = both cores to itself): {cpu_cmp / wall:.2f} over both "
        f"renders of the comparison, {cpu_ref1 / t_ref1:.2f} over Mitsuba's second image.", "",
        f"Machine: {os.cpu_count()} cores, {platform.processor() or platform.machine()}; OpenCL "
        f"device `{o['device']}` ({engine.queue.device.platform.version.strip()}).", "",
        "![relative error](mitsuba_cornell_error.png)", "",
    ]
    with atomic_path(RESULTS / "mitsuba_cornell.md") as tmp:
        tmp.write_text("\n".join(md), encoding="utf-8")
    print("\n".join(md))


if __name__ == "__main__":
    main()
