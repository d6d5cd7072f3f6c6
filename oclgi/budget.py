"""What a job will need, estimated and checked before any work is done.

A job too large for the device would otherwise end in an OpenCL error
(INVALID_BUFFER_SIZE, out of resources) after minutes of work, and one too
large for the host in swapping or the kernel's out-of-memory killer. Each
estimate here counts the job's large arrays, those that grow with its
pixels, points, seeds or photons (the scene's own buffers are small beside
them and already allocated), and :func:`check` compares:

- the largest single device buffer with CL_DEVICE_MAX_MEM_ALLOC_SIZE,
- all device buffers together with CL_DEVICE_GLOBAL_MEM_SIZE, on a device
  with memory of its own (a GPU),
- the host arrays with the memory the system has available now, and on a
  CPU device (whose buffers are host memory) the device buffers with them.

The estimates are rough and lean to the large side (a 1024x1024 DETP
render on a CPU device peaked at 235 bytes a pixel, the estimate says 268),
and they are held against the limits that bind: PoCL states a global memory
of a fraction of the host's (6 GiB of 23 here) but its buffers are host
memory and grow past it (an 8192x8192 render peaks at 11.6 GiB and
completes), so a CPU device's total is held against the host's available
memory instead; the one-buffer limit holds on every device.

>>> need = Need("a 16384x16384 image", {"radiance": 16384 * 16384 * 16}, 0, "use a smaller width/height")
>>> need.device_total / 2**30
4.0
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from . import params
from .errors import OclgiError

DEFAULT_K = 50  # Photon Maps' and Ray Maps' default k (oclgi/estimators/photon_map.py)

GIB = float(1 << 30)
SEGMENT_BYTES = 48  # oclgi.cl.layout.Segment
# The device buffers every estimator of a method keeps per query point,
# bytes per point: positions, normals, sums, irradiance, and the index built
# over the points (Photon Maps' neighbour lists: point_buffers).
POINT_BUFFERS = {
    "detp": {"positions": 16, "normals": 16, "sums": 24, "irradiance": 16},
    "impact": {"positions": 16, "barycentrics": 8, "irradiance": 16},
    "photon_map": {"positions": 16, "normals": 16, "sums": 24, "irradiance": 16, "query order": 4, "radii": 4},
    "ray_map_knn": {"positions": 16, "normals": 16, "sums": 24, "irradiance": 16, "query order": 4, "radii": 4},
}
# The k-nearest methods, whose tests and studies may read k neighbours per point.
KNN_METHODS = ("photon_map", "ray_map_knn")
INDEX_BYTES = {"detp_disc_index": 64, "detp_ray_map": 48, "detp_sphere_cache": 32}  # the variants' index
# Host bytes per query point of one estimate: its irradiance and sums read
# back (16 + 24) and the temporaries of checking and packing points.
POINT_HOST_BYTES = 96
# A rendered pixel on the host: the camera's points (40), the estimate (40),
# the radiance and pixels (32), and the images' encoding when written (32).
# (On a CPU device the device buffers come on top: 1024x1024 pixels of DETP
# peaked at 235 bytes a pixel in all, this estimate says 268.)
PIXEL_HOST_BYTES = 144
# A rendered pixel on the device beside the estimator: the shading's copies
# of the points, its radiance and its pixels (oclgi/engine.py's shade).
PIXEL_BUFFERS = {"shaded positions": 16, "shaded normals": 16, "radiance": 16, "pixels": 4}
# Final gathering (gather = N) keeps N hits per query point, each a disc of
# the estimator's with its own sums, plus the hits' weights, direct light and
# the host's copies while they are made: a 320x180 Sponza render at N = 64
# (3.7 million hits) peaked 257 bytes a hit above the same render without.
# (+16 on the device since the rays carry the emission they see past mirrors and glass)
GATHER_HIT_DEVICE_BYTES = 80  # weight, emission, direct light (16 each), ray state (32), beside the disc's points
GATHER_HIT_HOST_BYTES = 160
# The host's share of one stored estimate in a study (float64 RGB, and the
# list it is stacked from).
STUDY_VALUE_BYTES = 2 * 3 * 8
RANDOM_POINT_HOST_BYTES = 256  # a random point's float64 draws and temporaries, and its packed copy
SEED_HOST_BYTES = 40  # a Python int in the seeds' list
POSE_HOST_BYTES = 256  # a 4x4 float64 pose and its array header
FRAME_HOST_BYTES = 1024  # a frame's row of timings
# A run whose estimated time exceeds this gets a notice with the estimate.
NOTICE_SECONDS = 60.0


def gib(nbytes: float) -> str:
    """A size as messages write it: GiB from 1 GiB up, else MiB or KiB."""
    for unit, size in (("GiB", GIB), ("MiB", float(1 << 20))):
        if nbytes >= size:
            return f"{nbytes / size:.1f} {unit}"
    return f"{nbytes / 1024:.1f} KiB"


@dataclass
class Need:
    """What a job needs: ``what`` names it in messages ("a 16384x16384
    image"), ``device`` maps each large device buffer to its bytes, ``host``
    counts host bytes, ``hint`` says how to make it smaller."""

    what: str
    device: dict = field(default_factory=dict)
    host: int = 0
    hint: str = ""

    @property
    def device_total(self) -> int:
        return int(sum(self.device.values()))

    @property
    def device_largest(self) -> int:
        return int(max(self.device.values(), default=0))


def device_limits(device) -> tuple[int, int]:
    """(largest buffer, all buffers) the device allows, in bytes."""
    return int(device.max_mem_alloc_size), int(device.global_mem_size)


def meminfo(key: str) -> int | None:
    """A line of Linux's /proc/meminfo in bytes ("MemAvailable", "MemTotal"), None where there is none."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def host_available() -> int | None:
    """Bytes of memory the host can give now without swapping (Linux's
    MemAvailable, else the free pages), None where the system does not say."""
    available = meminfo("MemAvailable")
    if available is not None:
        return available
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def shares_host_memory(device) -> bool:
    """Whether the device's buffers live in the host's memory (a CPU
    device, as PoCL's): then they count against the host's memory too."""
    import pyopencl as cl

    return bool(device.type & cl.device_type.CPU)


def check(need: Need, device=None) -> Need:
    """Raise OclgiError if ``need`` does not fit ``device`` (None: check the
    host only) or the host's available memory; return it otherwise."""
    hint = f"; {need.hint}" if need.hint else ""
    shared = device is not None and shares_host_memory(device)
    if device is not None and need.device:
        largest, total = device_limits(device)
        if shared:
            total = max(total, need.device_total)  # bounded by the host's memory below
        if need.device_largest > largest or need.device_total > total:
            biggest = max(need.device, key=need.device.get)
            raise OclgiError(f"{need.what} needs about {gib(need.device_total)} of device memory, "
                             f"{gib(need.device_largest)} in its largest buffer ({biggest}) (the device allows "
                             f"{gib(largest)} in one buffer, {gib(total)} in all){hint}")
    available = host_available()
    host = need.host + (need.device_total if shared else 0)
    if available is not None and host > available:
        raise OclgiError(f"{need.what} needs about {gib(host)} of host memory ({gib(available)} is "
                         f"available){hint}")
    return need


# -- the jobs ------------------------------------------------------------------------------


def batch_buffers(photons: int, max_depth: int, batch_bytes: int) -> dict:
    """The tracer's reused buffers: one batch of paths (oclgi/engine.py's batching)."""
    paths = max(1, min(photons, batch_bytes // (max_depth * SEGMENT_BYTES)))
    return {"photon segments": paths * max_depth * SEGMENT_BYTES, "path lengths": paths * 4}


def point_buffers(method: str, n: int, k: int | None = None) -> dict:
    """An estimator's buffers over ``n`` query points, each by its size."""
    per_point = dict(POINT_BUFFERS.get(method, POINT_BUFFERS["detp"]))
    if method in INDEX_BYTES:
        per_point["index over the points"] = INDEX_BYTES[method]
    if method in KNN_METHODS:  # k ids and k distances per point
        k = int(k) if params.integral(k) else DEFAULT_K
        per_point["neighbour ids"] = per_point["neighbour distances"] = 4 * k
    return {name: n * size for name, size in per_point.items()}


def gather_buffers(method: str, n_points: int, gather: int, k: int | None = None) -> tuple[dict, int]:
    """Final gathering's device buffers and host bytes: a disc at each of
    the ``gather`` hits of each point (0: none)."""
    hits = math.ceil(n_points * max(float(gather or 0), 0.0))  # (an irradiance cache: a fraction of a ray a point)
    if not hits:
        return {}, 0
    device = {f"gather hits' {name}": size for name, size in point_buffers(method, hits, k).items()}
    device["gather hits' weights and direct light"] = hits * GATHER_HIT_DEVICE_BYTES
    return device, hits * GATHER_HIT_HOST_BYTES


def _rays(gather) -> str:
    """Rays a point in words: a whole number, or an irradiance cache's fraction."""
    return f"{int(gather):,}" if float(gather).is_integer() else f"{gather:.3g}"


def _gather_hint(gather: int, hint: str) -> str:
    return "use fewer gather rays or " + hint.removeprefix("use ") if gather else hint


def irradiance_need(n_points: int, method: str, photons: int, max_depth: int, batch_bytes: int,
                    k: int | None = None, gather: int = 0) -> Need:
    extra, extra_host = gather_buffers(method, n_points, gather, k)
    device = {**point_buffers(method, n_points, k), **batch_buffers(photons, max_depth, batch_bytes), **extra}
    return Need(f"an estimate at {n_points:,} points" + (f" with {_rays(gather)} gather rays each" if gather else ""),
                device, n_points * POINT_HOST_BYTES + extra_host, _gather_hint(gather, "use fewer points"))


def render_need(width: int, height: int, method: str, photons: int, max_depth: int, batch_bytes: int,
                k: int | None = None, gather: int = 0) -> Need:
    n = width * height
    extra, extra_host = gather_buffers(method, n, gather, k)
    device = {**point_buffers(method, n, k), **batch_buffers(photons, max_depth, batch_bytes),
              **{name: n * size for name, size in PIXEL_BUFFERS.items()}, **extra}
    return Need(f"a {width}x{height} image" + (f" with {_rays(gather)} gather rays a pixel" if gather else ""),
                device, n * PIXEL_HOST_BYTES + extra_host, _gather_hint(gather, "use a smaller width/height"))


def camera_need(width: int, height: int) -> Need:
    n = width * height
    return Need(f"the visible points of a {width}x{height} camera", {"points": n * 16, "normals": n * 16,
                "barycentrics": n * 8}, n * 40 + n * POINT_HOST_BYTES, "use a smaller width/height")


def random_points_need(n: int) -> Need:
    """Random surface points drawn on the host: the draws, positions and
    normals in float64, and the packed float32 points (oclgi/study/run.py)."""
    return Need(f"{n:,} random points", {}, n * RANDOM_POINT_HOST_BYTES, "use fewer points")


def seeds_need(n_seeds: int) -> Need:
    return Need(f"a study of {n_seeds:,} seeds", {}, n_seeds * SEED_HOST_BYTES, "use fewer seeds")


def study_need(n_points: int, n_seeds: int, n_rows: int) -> Need:
    """A study's estimates kept on the host: every (configuration, photon
    count) row keeps one RGB estimate per seed and point."""
    host = n_rows * n_seeds * n_points * STUDY_VALUE_BYTES + n_points * POINT_HOST_BYTES * 4
    return Need(f"a study of {n_rows} configurations x {n_seeds:,} seeds at {n_points:,} points", {}, host,
                "use fewer seeds, points or photon counts")


def frames_need(frames: int) -> Need:
    return Need(f"an animation of {frames:,} frames", {}, frames * (POSE_HOST_BYTES + FRAME_HOST_BYTES),
                "use fewer frames")


def frames(value, name: str = "frames") -> int:
    """An animation's frame count (oclgi.params.frames), refused beyond its
    cap with what its poses and timings alone would take."""
    n = params.integral(value)
    if n is not None and n > params.MAX_FRAMES:
        raise params.ParamError(name, f"expected an integer in 1..{params.MAX_FRAMES:,}, got {n} (its poses and "
                                      f"timings alone would take about {gib(frames_need(n).host)} of memory)")
    return params.frames(value, name)


def duration(seconds: float) -> str:
    """A rough duration in the unit that reads best."""
    for unit, size in (("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.0f} {unit}"
    return f"{seconds:.0f} seconds"


def time_notice(done: int, seconds: float, total: int) -> str | None:
    """A notice of the whole run's time, extrapolated from its first ``done``
    paths of ``total`` traced and estimated in ``seconds``; None when the run
    is short (under NOTICE_SECONDS)."""
    if done <= 0 or done >= total or not math.isfinite(seconds):
        return None
    estimate = seconds * total / done
    if estimate < NOTICE_SECONDS:
        return None
    return (f"{total:,} photon paths will take about {duration(estimate)} on this device "
            f"(from the first {done:,} in {seconds:.1f}s); use fewer photons for a quicker run")
