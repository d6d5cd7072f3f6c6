"""Choosing the OpenCL device.

Order of precedence: an explicit ``device`` argument (the CLI's ``--device``),
then ``OCLGI_DEVICE``, then ``PYOPENCL_CTX`` (pyopencl's own convention), then
the first CPU device of a PoCL platform, then the first device found.

A device spec is ``"P:D"`` (platform and device indices, as ``oclgi info``
lists them) or a case-insensitive substring of the platform or device name.
"""

from __future__ import annotations

import os
import tempfile
import threading

import pyopencl as cl

from ..errors import OclgiError

# PoCL compiles a kernel anew for every work-group size, global offset and
# grid size class it is launched with ("specialisation"); one generic
# version per kernel serves every launch instead. Measured: no slower on
# oclgi's loop-bound kernels (PoCL does not vectorise them across
# work-items), fewer compiles per run, and a kernel cache that a tiny run
# (``oclgi warm``) fills for any later size. Set before PoCL reads it at its
# first compile; a user's own setting wins.
os.environ.setdefault("POCL_WORK_GROUP_SPECIALIZATION", "0")

INSTALL_HINT = "install an OpenCL runtime, e.g. `apt-get install pocl-opencl-icd` (or run `make setup`)"

# Variables that decide which OpenCL devices a process sees: the ICD loader's
# (where the runtimes are listed) and PoCL's. Set wrongly, they leave the
# runtime installed but silent, and the message must blame them, not a
# missing runtime. (POCL_CACHE_DIR, PoCL's folder for compiled kernels, is
# checked on its own: check_cache_dir.)
RUNTIME_VARIABLES = ("OCL_ICD_VENDORS", "OCL_ICD_FILENAMES", "OPENCL_VENDOR_PATH", "POCL_DEVICES")


def runtime_settings() -> list[str]:
    """``NAME=value`` of each of RUNTIME_VARIABLES that is set."""
    return [f"{name}={os.environ[name]}" for name in RUNTIME_VARIABLES if os.environ.get(name, "").strip()]


def check_cache_dir() -> None:
    """PoCL writes every compiled kernel under POCL_CACHE_DIR; when it cannot,
    it fails builds without a reason, or shows no device at all. Tried the
    way PoCL uses it: the folder made if missing, a file written in it."""
    value = os.environ.get("POCL_CACHE_DIR", "").strip()
    if not value:
        return
    if os.path.exists(value) and not os.path.isdir(value):
        problem = "not a folder"
    else:
        try:
            os.makedirs(value, exist_ok=True)
            with tempfile.TemporaryFile(dir=value):
                pass
            return
        except OSError as exc:
            problem = (exc.strerror or str(exc)).lower()
    raise OclgiError(f"POCL_CACHE_DIR={value} cannot hold PoCL's compiled kernels ({problem}): "
                     "point it at a writable folder, or unset it")


def no_device_message() -> str:
    """Why no device answers, naming the variables that may be the cause."""
    check_cache_dir()
    settings = runtime_settings()
    if not settings:
        return f"no OpenCL platform found: {INSTALL_HINT}"
    named = ", ".join(settings)
    verb = "is" if len(settings) == 1 else "are"
    them = "it" if len(settings) == 1 else "them"
    return (f"no OpenCL device found ({named} {verb} set and may hide the devices: correct or unset {them}); "
            f"if that is not it, {INSTALL_HINT}")


def list_devices() -> list[tuple[int, int, cl.Device]]:
    """All (platform index, device index, device) triples; empty when none."""
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    out = []
    for pi, p in enumerate(platforms):
        try:
            devs = p.get_devices()
        except cl.Error:
            continue
        out.extend((pi, di, d) for di, d in enumerate(devs))
    return out


def _match(spec: str, devices):
    spec = spec.strip()
    if ":" in spec and all(s.strip().isdigit() for s in spec.split(":", 1)):
        pi, di = (int(s) for s in spec.split(":", 1))
        for p, d, dev in devices:
            if (p, d) == (pi, di):
                return dev
        raise OclgiError(f"no OpenCL device {spec!r}; `oclgi info` lists them")
    if spec.isdigit():
        # pyopencl's PYOPENCL_CTX accepts a bare platform index.
        for p, _d, dev in devices:
            if p == int(spec):
                return dev
        raise OclgiError(f"no OpenCL platform {spec!r}; `oclgi info` lists them")
    low = spec.lower()
    for _p, _d, dev in devices:
        if low in dev.name.lower() or low in dev.platform.name.lower():
            return dev
    raise OclgiError(f"no OpenCL device matches {spec!r}; `oclgi info` lists them")


def choose_device(spec: str | None = None) -> cl.Device:
    devices = list_devices()
    if not devices:
        raise OclgiError(no_device_message())
    spec = spec or os.environ.get("OCLGI_DEVICE") or os.environ.get("PYOPENCL_CTX")
    if spec:
        return _match(spec, devices)
    for _p, _d, dev in devices:
        if "portable computing language" in dev.platform.name.lower() and dev.type & cl.device_type.CPU:
            return dev
    return devices[0][2]


def check_device(dev: cl.Device) -> None:
    """The engine needs 64-bit integer atomics for its order-independent sums."""
    ext = dev.extensions.split()
    if "cl_khr_int64_base_atomics" not in ext:
        raise OclgiError(f"OpenCL device {dev.name!r} lacks cl_khr_int64_base_atomics, which oclgi's "
                         "fixed-point accumulation needs; choose another device with --device / OCLGI_DEVICE")


# One context per device and process, shared by every engine on that device:
# programs belong to a context, and building one again for a new context
# costs about 30 ms a program even when PoCL finds it in its cache (it
# preprocesses the source to look it up), which a notebook or a server that
# makes several engines paid over and over. Each engine has its own queue.
_contexts: dict[int, cl.Context] = {}
_contexts_lock = threading.Lock()


def create_context(spec: str | None = None) -> tuple[cl.Context, cl.CommandQueue]:
    """The device's context (shared, see above) and a new in-order queue on it."""
    check_cache_dir()
    dev = choose_device(spec)
    check_device(dev)
    with _contexts_lock:
        ctx = _contexts.get(dev.int_ptr)
        if ctx is None:
            ctx = _contexts[dev.int_ptr] = cl.Context([dev])
    return ctx, cl.CommandQueue(ctx)


def _kind(dev: cl.Device) -> str:
    """CPU, GPU or ACCELERATOR (PoCL also sets the DEFAULT bit, which says nothing)."""
    for name in ("GPU", "CPU", "ACCELERATOR"):
        if dev.type & getattr(cl.device_type, name):
            return name
    return cl.device_type.to_string(dev.type)


def describe_devices() -> str:
    devices = list_devices()
    if not devices:
        return no_device_message()
    try:
        chosen = choose_device()
    except OclgiError:
        chosen = None
    lines = []
    for pi, di, d in devices:
        mark = "*" if chosen is not None and d.int_ptr == chosen.int_ptr else " "
        lines.append(f"{mark} {pi}:{di}  {d.platform.name} | {d.name} | {_kind(d)} | "
                     f"{d.max_compute_units} units | {d.global_mem_size / 2**30:.1f} GiB "
                     f"(max alloc {d.max_mem_alloc_size / 2**30:.1f} GiB) | {d.version}")
    lines.append("* = default (override with --device P:D, OCLGI_DEVICE or PYOPENCL_CTX)")
    return "\n".join(lines)
