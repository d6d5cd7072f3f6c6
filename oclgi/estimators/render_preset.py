"""The default estimate of ``oclgi render``: the samples and DETP options
that reached a path tracer's error fastest on the image benchmark of
issue 31 (``bench/image_equal_time.py``).

Measured (bench/README.md, "Images at equal error"; 128 x 128 against
Mitsuba 3's ``llvm_ad_rgb`` at 2 x 8,192 spp, on 2 cores, one run side by
side): 16 samples a pixel, each with its own exact direct light from 4
light samples, and the indirect light gathered with 128 rays at one pixel
in 3 x 3 (irradiance caching, oclgi/estimators/irradiance_cache.py) reach
Mitsuba's error at 256 spp in 0.40x its time on the Cornell box, at most
0.24x on CornellBox-Sphere (glass) and 0.57-1.10x (four runs) on
textured Sponza under sun and sky: the only setting measured that reaches
that error on all three. Cheaper ones (2 to 6 samples, 32 to 96 rays at
one pixel in 4 x 4) are faster at Mitsuba's 64-spp error but stop above
the 256-spp one on the Cornell box; the photons' own estimate at one
sample a pixel (the method's default) reaches it only on CornellBox-Sphere.
Light samples alone (``direct_mis = "light"``) beat the power heuristic
(to the 256-spp error in one run: 0.53 s against 0.58 s on the Cornell
box, 1.34 s against 2.23 s in Sponza): the lights are small against what a diffuse
point sees, so its cosine samples seldom find them.

Bounds, for large images (a cost rule, not a measured optimum): the
samples keep to 2^22 a render (16 a pixel up to 512 x 512, 1 past 2048 x
2048) and the gathered points' rays to 2^21 (the spacing widens past 3
from about 256 x 256 x 4).

Given --spp or any of PRESET_KEYS, or ``--plain``, the command takes the
method's own defaults (one sample a pixel, the photons' estimate); the
Python API always does (``Engine.render``). The viewer's "render this
view" takes the preset unless the page asks for "plain"
(oclgi/viewer/render_process.py, ``render_args``).
"""

from __future__ import annotations

import math

PRESET_KEYS = ("direct", "direct_samples", "direct_mis", "gather", "gather_spacing", "radius_mode")
SPP, RAYS, SPACING, LIGHT_SAMPLES, MIS = 16, 128, 3, 4, "light"
MAX_SAMPLES, MAX_HITS = 1 << 22, 1 << 21


def render_settings(family: str, options: dict, spp_given: bool, width: int, height: int) -> dict:
    """The samples per pixel (``spp``) and options the preset adds for a
    ``width`` x ``height`` render of a method of ``family``: none when the
    method is not DETP, when ``--spp`` or any of PRESET_KEYS is given, or
    when no emitted light is counted (the direct light is then left out on
    purpose)."""
    if family != "detp" or spp_given or any(k in options for k in PRESET_KEYS) \
            or options.get("count_emitted") is False:
        return {}
    pixels = max(int(width) * int(height), 1)
    spp = max(1, min(SPP, MAX_SAMPLES // pixels))
    spacing = max(SPACING, math.ceil(math.sqrt(pixels * RAYS / MAX_HITS)))
    return {"spp": spp, "direct": "exact", "direct_samples": LIGHT_SAMPLES, "direct_mis": MIS, "gather": RAYS,
            "gather_spacing": min(spacing, 64)}


def describe(settings: dict) -> str:
    """One line for the command's output: what the preset chose."""
    return (f"estimate: {settings['spp']} samples a pixel with exact direct light, the indirect gathered with "
            f"{settings['gather']} rays at one pixel in {settings['gather_spacing']} x {settings['gather_spacing']} "
            f"(the fastest to a path tracer's error, bench/README.md; --plain for the photons' estimate alone)")
