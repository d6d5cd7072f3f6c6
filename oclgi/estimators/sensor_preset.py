"""The default estimate of ``oclgi irradiance`` (sensor points): the DETP
options that reached a given error fastest on the benchmarks of issue 31.

Measured (bench/README.md, "Accuracy"; 256 points against Mitsuba 3, 10 s
on 2 cores): under an area light over 101k-triangle foliage, a sky over a
118k-triangle courtyard and the Cornell box's ceiling light, adaptive radii
with exact direct light and final gathering of 1,024 rays a point read
median errors of 0.20%, 0.79% and 0.40% with no point off by 2x, where the
plain disc estimate (fixed radius, photons for the direct light) read
1.41%, 2.73% and 1.20% with 16, 9 and 0 points off by 2x; under a sun the
same 0.12% and 1.7% against 1.24% and 4.16%. So the command takes them
unless told otherwise (``--plain``, or any of the three options given).

The rays: 1,024 a point up to 256 points, then as many as keep the hits
(one disc each, with its own adaptive radius) at the benchmark's 2^18, down
to 16 rays a point at 16,384 points; past that no gathering (the direct
light and the radii stay). A cost bound, not a measured optimum: 10,000
sensors in the Cornell box at 2^22 hits took 52 s and 2.1 GB where the
plain estimate takes 1 s.

The Python API keeps each method's own defaults (``Engine.irradiance``
is the plain estimator unless asked): these are the command's.
"""

from __future__ import annotations

PRESET_KEYS = ("radius_mode", "direct", "gather")
RAYS, MIN_RAYS, MAX_HITS = 1024, 16, 1 << 18


def gather_rays(points: int) -> int:
    """The gather rays a point of a run over ``points`` points takes (0: none)."""
    n = min(RAYS, MAX_HITS // max(int(points), 1))
    return n if n >= MIN_RAYS else 0


def sensor_options(family: str, options: dict, points: int) -> dict:
    """The options the preset adds to ``options`` for a run of a method of
    ``family`` over ``points`` points: none when the method is not DETP,
    when ``options`` set any of PRESET_KEYS, or when they count no emitted
    light (``count_emitted`` false: the direct light is then left out on
    purpose)."""
    if family != "detp" or any(k in options for k in PRESET_KEYS) or options.get("count_emitted") is False:
        return {}
    out = {"radius_mode": "adaptive", "direct": "exact"}
    n = gather_rays(points)
    if n:
        out["gather"] = n
    return out


def describe(options: dict) -> str:
    """One line for the command's output: what the preset chose."""
    gather = options.get("gather")
    return ("estimate: adaptive radii, exact direct light" +
            (f", final gathering with {gather:,} rays a point" if gather else " (too many points to gather)") +
            " (the most accurate at equal time, bench/README.md; --plain for the disc estimate alone)")
