"""Mitsuba reference images for the equal-time benches, kept between runs,
and the relative error against them (bench/caustic_equal_time.py,
bench/spp_equal_time.py)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from oclgi.photometry import LUMINANCE
from oclgi.study import mitsuba as mitsuba_reference


def reference_pair(engine, size: int, spp: int, variant: str, out: Path):
    """(a, b, seconds): two Mitsuba renders of ``size`` x ``size`` at ``spp``
    (seeds 1000 and 2000) and the seconds they took, from ``out`` when an
    earlier run left them there (the reference is the slow part)."""
    cached = out / f"reference_{size}_{spp}_{variant}.npz"
    if cached.is_file():
        with np.load(cached) as z:
            return z["a"], z["b"], float(z["seconds"])
    t0 = time.perf_counter()
    a = mitsuba_reference.render(engine, width=size, height=size, spp=spp, seed=1000, variant=variant)
    b = mitsuba_reference.render(engine, width=size, height=size, spp=spp, seed=2000, variant=variant)
    seconds = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    np.savez(cached, a=a, b=b, seconds=seconds)
    return a, b, seconds


def rel_rms(image, ref, region) -> float:
    """Relative RMS error of the luminance of ``image`` against ``ref`` over the
    pixels of ``region`` (those where the reference is not black)."""
    a, b = image[region] @ LUMINANCE, ref[region] @ LUMINANCE
    keep = b > 0
    return float(np.sqrt(np.mean(((a[keep] - b[keep]) / b[keep]) ** 2)))
