"""What the equal-time benches against Mitsuba share (bench/caustic_equal_time.py,
bench/spp_equal_time.py): their options, the Mitsuba reference images, kept
between runs, the relative error against them, Mitsuba's timed sweep and the
error-against-time plot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common import ROOT, arguments, cached_pair, figure, timed
from oclgi.photometry import LUMINANCE
from oclgi.study import mitsuba as mitsuba_reference


def parse_args(doc: str, name: str, ref_spp: int, photons: str, spp: str, quick: tuple, **extra):
    """The options both benches take, and ``extra`` (common.arguments); ``--quick``
    sets 48 x 48 and ``quick``'s (ref-spp, photons, spp); the lists parsed."""
    args = arguments(doc, size=96, ref_spp=(ref_spp, "per reference image (two are rendered)"),
                     variant="llvm_ad_rgb", photons=photons, spp=spp, out=ROOT / "out" / name, **extra,
                     quick=dict(size=48, **dict(zip(("ref_spp", "photons", "spp"), quick))))
    args.photons = [int(float(x)) for x in args.photons.split(",")]
    args.spp = [int(x) for x in args.spp.split(",")]
    return args


def reference_pair(engine, size: int, spp: int, variant: str, out: Path):
    """(a, b, seconds): two Mitsuba renders of ``size`` x ``size`` at ``spp``
    (seeds 1000 and 2000) and the seconds they took, from ``out`` when an
    earlier run left them there (the reference is the slow part)."""
    return cached_pair(out / f"reference_{size}_{spp}_{variant}.npz", lambda seed: mitsuba_reference.render(
        engine, width=size, height=size, spp=spp, seed=seed, variant=variant), (1000, 2000))


def rel_rms(image, ref, region) -> float:
    """Relative RMS error of the luminance of ``image`` against ``ref`` over the
    pixels of ``region`` (those where the reference is not black)."""
    a, b = image[region] @ LUMINANCE, ref[region] @ LUMINANCE
    keep = b > 0
    return float(np.sqrt(np.mean(((a[keep] - b[keep]) / b[keep]) ** 2)))


def add_row(rows: list, *row) -> None:
    """A (renderer, budget, seconds, error) row, printed as it comes."""
    rows.append(row)
    print(*row, flush=True)


def mitsuba_sweep(rows: list, engine, size: int, spps, variant: str, error) -> None:
    """Mitsuba's path tracer at each of ``spps``, timed after a warm-up (its
    JIT), a row each with ``error(image)``."""
    mitsuba_reference.render(engine, width=size, height=size, spp=4, seed=0, variant=variant)
    for spp in spps:
        t, img = timed(mitsuba_reference.render, engine, width=size, height=size, spp=spp, seed=7, variant=variant)
        add_row(rows, f"Mitsuba 3 path ({variant})", f"{spp:,} spp", t, error(img))


def plot(path: Path, panels, ylabel: str, figsize, dpi: int) -> None:
    """Error against seconds, log-log, a panel per (title, {renderer: [(seconds,
    error)]}, the reference's own error); nothing without matplotlib."""
    try:
        fig, axes = figure(1, len(panels), figsize=figsize, squeeze=False)
    except ImportError:
        return
    for ax, (title, curves, ref_error) in zip(axes[0], panels):
        for name, pts in curves.items():
            ax.loglog(*zip(*pts), "o-", label=name)
        ax.axhline(ref_error, color="grey", ls=":", label="reference's own error")
        ax.set(title=title, xlabel="seconds")
    axes[0, 0].set_ylabel(ylabel)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
