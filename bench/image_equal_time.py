"""Images at equal error against Mitsuba 3 (issue 31, item 3): the time each
renderer takes to reach two error levels on the Cornell box, CornellBox-Sphere
(clear glass) and textured Sponza under a sun and a sky.

The reference: Mitsuba's path tracer (``--variant``, default llvm_ad_rgb)
at ``--ref-spp`` samples per pixel, two seeds, their mean (its own error,
from the halves, is reported). The error: the mean relative error of
luminance over the pixels the reference lights. The levels: the errors
Mitsuba reaches at the samples per pixel of ``--levels`` (default 64 and
256). Each renderer is swept (Mitsuba over ``--spp``, each oclgi setting of
``--configs`` over ``--photons``), each run timed in wall-clock seconds
after a warm-up (Mitsuba's JIT at each spp, oclgi's kernel builds), in this process one
after another; a curve's time at a level is interpolated in log-log
(blank where the sweep does not reach it). Ratio: oclgi's time over
Mitsuba's at the same level (the issue's goal: <= 0.5).

Writes ``bench/results/image_equal_time.md`` and, per scene,
``image_equal_time_<scene>.png``: the reference, Mitsuba at the first level
and each oclgi setting's run nearest to it in error, over their error maps
(blue: lower than the reference, red: higher, +-25% at full colour).

Usage: ``.venv/bin/python bench/image_equal_time.py [--scenes cornell,cornell_sphere,sponza]
[--width 128] [--ref-spp 8192] [--spp 16,64,256,1024] [--photons 1e5,3e5,1e6,3e6]
[--configs "spp=1;direct=exact,spp=4;direct=exact"]`` (``--quick``: 48 pixels
wide, a smoke run). Needs ``pip install 'oclgi[mitsuba]'``.
"""

from __future__ import annotations

import numpy as np

from common import RESULTS, ROOT, arguments, cached_pair, engine as make_engine, figure, machine_line, timed, write
from oclgi import params
from oclgi.photometry import LUMINANCE
from oclgi.study import mitsuba as mitsuba_reference
from oclgi.study.image_compare import error_colours

SCENES = {"cornell": "cornell_box.toml", "cornell_sphere": "cornell_sphere.toml", "sponza": "sponza_textured.toml"}
ERROR_SCALE = 0.25  # of the error maps: full colour at +-25%


def parse_config(text: str) -> dict:
    """"spp=4;direct=exact" -> {"spp": 4, "direct": "exact"} (values read as -O's are: numbers, true/false, words)."""
    return dict(params.option_text(item) for item in filter(None, text.split(";")))


def mean_rel(image, ref, lit) -> float:
    a, b = image[lit] @ LUMINANCE, ref[lit] @ LUMINANCE
    return float(np.mean(np.abs(a - b) / b))


def time_at(curve, level: float) -> tuple[float, bool]:
    """The time a curve of (seconds, error) reaches ``level`` at, in log-log,
    and whether that is a bound only: (the fastest run's time, True) where
    every run is already below the level (the sweep starts past it);
    (NaN, False) where no run reaches it."""
    pts = sorted(curve)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if min(e0, e1) <= level <= max(e0, e1) and e0 != e1:
            f = (np.log(level) - np.log(e0)) / (np.log(e1) - np.log(e0))
            return float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0)))), False
    below = [t for t, e in pts if e <= level]
    return (min(below), True) if below else (float("nan"), False)


def srgb(radiance, exposure):
    x = np.clip(radiance * exposure, 0.0, 1.0)
    return np.round(255 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)).astype(np.uint8)


def bench_scene(name, args):
    engine = make_engine(ROOT / "scenes" / SCENES[name])
    cam = engine.scene.camera
    w = args.width
    h = max(1, round(w * cam.height / cam.width))
    a, b, ref_seconds = cached_pair(args.out / f"{name}_{w}x{h}_{args.ref_spp}_{args.variant}.npz",
                                    lambda seed: mitsuba_reference.render(engine, width=w, height=h, spp=args.ref_spp,
                                                                          seed=seed, variant=args.variant),
                                    (1000, 2000))
    ref = 0.5 * (a + b)
    lit = (ref @ LUMINANCE) > 0
    ref_error = mean_rel(a, b, lit) / 2 ** 1.5  # a half's error against the other over 2, the mean's: / sqrt 2
    runs = {}  # renderer -> [(seconds, error, image, budget)]
    label = f"Mitsuba 3 path ({args.variant})"
    for spp in sorted(set(args.spp) | set(args.levels)):
        mitsuba_reference.render(engine, width=w, height=h, spp=spp, seed=0, variant=args.variant)  # its JIT
        t, img = timed(mitsuba_reference.render, engine, width=w, height=h, spp=spp, seed=7, variant=args.variant)
        runs.setdefault(label, []).append((t, mean_rel(img, ref, lit), img, f"{spp} spp"))
        print(name, label, spp, f"{t:.2f} s", f"{runs[label][-1][1]:.4f}", flush=True)
    for text in args.configs:
        cfg = parse_config(text)
        engine.render(width=w, height=h, photons=args.photons[0], **cfg)  # kernel builds
        for n in args.photons:
            t, r = timed(engine.render, width=w, height=h, photons=n, **cfg)
            key = f"oclgi {text or 'default'}"
            runs.setdefault(key, []).append((t, mean_rel(r.radiance, ref, lit), r.radiance, f"{n:,} photons"))
            print(name, key, f"{n:,}", f"{t:.2f} s", f"{runs[key][-1][1]:.4f}", flush=True)
    mitsuba = {b: e for _, e, _, b in runs[label]}
    levels = [mitsuba[f"{spp} spp"] for spp in args.levels]
    curves = {k: [(t, e) for t, e, _, _ in v] for k, v in runs.items()}
    equal = {k: [time_at(c, lv) if k != label else (next(t for t, e, _, b in runs[label] if e == lv), False)
                 for lv in levels] for k, c in curves.items()}
    pictures(name, ref, lit, runs, label, levels[0])
    return dict(name=name, size=(w, h), ref_spp=args.ref_spp, ref_seconds=ref_seconds, ref_error=ref_error,
                runs={k: [(t, e, b) for t, e, _, b in v] for k, v in runs.items()}, levels=levels, equal=equal,
                mitsuba=label, triangles=engine.scene.n_triangles)


def pictures(name, ref, lit, runs, label, level):
    """The reference, Mitsuba at ``level`` and each oclgi setting nearest
    to it, over their signed relative error maps."""
    try:
        fig, axes = figure(2, len(runs) + 1, figsize=(3 * (len(runs) + 1), 5.6), squeeze=False)
    except ImportError:
        return
    y = ref @ LUMINANCE
    exposure = 0.18 / float(np.exp(np.mean(np.log(y[lit]))))
    panels = [("reference", ref, None)]
    for k, v in runs.items():
        t, e, img, budget = min(v, key=lambda r: abs(np.log(r[1] / level)))
        panels.append((k.replace(";", "\n") + f"\n{budget}, {t:.2f} s, {e:.3f}", img, img))
    for col, (title, img, test) in enumerate(panels):
        axes[0, col].imshow(srgb(img, exposure))
        axes[0, col].set_title(title, fontsize=7)
        if test is not None:
            signed = np.where(lit, (test @ LUMINANCE - y) / np.where(lit, y, 1.0), 0.0)
            axes[1, col].imshow(error_colours(signed, ~lit, ERROR_SCALE))
        for row in (0, 1):
            axes[row, col].axis("off")
    fig.tight_layout()
    fig.savefig(RESULTS / f"image_equal_time_{name}.png", dpi=110)


def markdown(rows, machine, args) -> str:
    out = ["# Images at equal error against Mitsuba 3", "", machine, "",
           "Mean relative error of luminance over the pixels the reference lights; wall-clock seconds of "
           "each render after a warm-up; the levels are Mitsuba's errors at "
           f"{' and '.join(str(s) for s in args.levels)} spp; ratio = oclgi's time / Mitsuba's at a level "
           "(goal <= 0.5; blank: the sweep does not reach it; <=: its fastest run is already past the level, "
           "a bound).", ""]
    for r in rows:
        w, h = r["size"]
        out += [f"## {r['name']}: {w} x {h} pixels, {r['triangles']:,} triangles", "",
                f"Reference: Mitsuba, 2 x {r['ref_spp']:,} spp ({r['ref_seconds']:.0f} s), its own error about "
                f"{r['ref_error']:.4f}.", "", "| renderer | budget | seconds | error |", "|---|---|---:|---:|"]
        out += [f"| {k} | {b} | {t:.2f} | {e:.4f} |" for k, v in r["runs"].items() for t, e, b in v]
        out += ["", "| renderer | " + " | ".join(f"time to {lv:.4f}" for lv in r["levels"]) + " | ratios |",
                "|---|" + "---:|" * (len(r["levels"]) + 1)]
        base = [t for t, _ in r["equal"][r["mitsuba"]]]

        def cell(t, bound, unit=1.0):
            return "" if np.isnan(t) else ("<= " if bound else "") + f"{t / unit:.2f}"
        for k, ts in r["equal"].items():
            ratios = " / ".join(cell(t, b, m) for (t, b), m in zip(ts, base))
            out.append(f"| {k} | " + " | ".join(cell(t, b) for t, b in ts) + f" | {ratios} |")
        out += ["", f"![{r['name']}](image_equal_time_{r['name']}.png)", ""]
    return "\n".join(out) + "\n"


def main():
    args = arguments(__doc__, scenes=",".join(SCENES), width=128, ref_spp=(8192, "per reference image (two)"),
                     variant="llvm_ad_rgb", spp="16,64,256,1024", levels="64,256", photons="1e5,3e5,1e6,3e6",
                     configs=("spp=1;direct=exact,spp=4;direct=exact", "oclgi settings, comma-separated, "
                              "each key=value;key=value (empty: the default)"),
                     out=ROOT / "out" / "image_equal_time",
                     quick=dict(width=48, ref_spp=256, spp="4,16,64", levels="16,64", photons="3e4,1e5"))
    names = args.scenes.split(",")
    if not set(names) <= set(SCENES):
        raise SystemExit(f"--scenes: of {', '.join(SCENES)}, got {args.scenes!r}")
    args.spp = [int(x) for x in args.spp.split(",")]
    args.levels = [int(x) for x in args.levels.split(",")]
    args.photons = [int(float(x)) for x in args.photons.split(",")]
    args.configs = args.configs.split(",")
    rows = [bench_scene(name, args) for name in names]
    import oclgi

    md = markdown(rows, machine_line(oclgi.Engine(oclgi.load_file(ROOT / "scenes" / SCENES[names[0]]),
                                                  progress=False).queue.device), args)
    write("image_equal_time.md", md)
    print(md)


if __name__ == "__main__":
    main()
