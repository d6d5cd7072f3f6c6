"""The one program cache: every `.cl` file under ``kernels/`` is built here.

Each (file stem, define set) is built once per context, with ``-I`` on the
kernel folder (shared headers) and pyopencl's include folder (Random123's
Philox), ``-cl-denorms-are-zero`` (see ``_build``) and the constants that
host and device share (``cl/constants.py``). Kernel handles are fetched
once per built program, never per call, and each kernel's scalar argument
types are declared once from the compiled kernel's own argument list
(``set_scalar_arg_dtypes``): call sites pass plain Python numbers, and a
call with the wrong number of arguments fails at the call.

PoCL keeps its own binary cache keyed on the preprocessed source, so editing
a header rebuilds what includes it.

Compiler output (warnings, PoCL's "N warnings generated.") never reaches
the terminal unless ``OCLGI_COMPILER_OUTPUT=1`` (the command line's
``--verbose`` sets it): it is kept as the program's ``log``. A failed build
raises an :class:`OclgiError` whose first line names the file and the first
compiler error; the whole log follows on the next lines.

The kernel folder is found as ``OCLGI_KERNEL_DIR`` if set, else as the
``oclgi.kernels`` package (an installed copy ships the ``.cl`` and ``.h``
files there; in the source tree it maps to ``kernels/``).
"""

from __future__ import annotations

import functools
import os
import re
import sys
import tempfile
import threading
import time
import warnings
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

import numpy as np
import pyopencl as cl

from ..errors import OclgiError
from .constants import build_defines
from .device import check_cache_dir

COMPILER_OUTPUT_ENV = "OCLGI_COMPILER_OUTPUT"


def kernel_dir() -> Path:
    return _kernel_dir(os.environ.get("OCLGI_KERNEL_DIR"))


@functools.lru_cache(maxsize=8)
def _kernel_dir(env: str | None) -> Path:
    """The folder found for an OCLGI_KERNEL_DIR value (programs() asks in every move)."""
    if env:
        return Path(env)
    try:
        path = Path(str(resources.files("oclgi.kernels")))
        if (path / "oclgi_types.h").is_file():
            return path
    except ModuleNotFoundError:
        pass
    path = Path(__file__).resolve().parents[2] / "kernels"
    if (path / "oclgi_types.h").is_file():
        return path
    raise OclgiError("oclgi's OpenCL kernels were not found; reinstall the package")


def correctly_rounded_divide_sqrt(device: cl.Device) -> bool:
    """Whether the device can build with -cl-fp32-correctly-rounded-divide-sqrt."""
    try:
        return bool(device.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT)
    except (cl.Error, AttributeError):
        return False


def compiler_output_wanted() -> bool:
    return os.environ.get(COMPILER_OUTPUT_ENV, "").strip() not in ("", "0")


class KernelBuildError(OclgiError):
    """A kernel file that does not compile: an installation problem, not bad input.
    ``log`` holds the compiler's whole output."""

    exit_code = 1

    def __init__(self, message: str, log: str = ""):
        super().__init__(message)
        self.log = log


_SOURCE_NAME = re.compile(r"\S*tempfile_\w+\.cl(?=:)")


def _first_error(log: str) -> str:
    """The compiler's first error line."""
    for line in log.splitlines():
        line = line.strip()
        if line.startswith("error:") or ": error:" in line:
            return line.removeprefix("error:").strip()
    return "the compiler gave no reason"


# OpenCL C scalar types by name, as clGetKernelArgInfo spells them.
_SCALARS = {
    "char": np.int8, "uchar": np.uint8, "short": np.int16, "ushort": np.uint16,
    "int": np.int32, "uint": np.uint32, "long": np.int64, "ulong": np.uint64,
    "float": np.float32, "double": np.float64,
    "unsigned char": np.uint8, "unsigned short": np.uint16, "unsigned int": np.uint32,
    "unsigned long": np.uint64,
}


def scalar_arg_dtypes(kernel: cl.Kernel) -> list:
    """Per argument: the numpy dtype of a by-value scalar, else None (buffers,
    local memory, vectors, which callers pass as buffers or numpy arrays)."""
    private = cl.kernel_arg_address_qualifier.PRIVATE
    out = []
    for i in range(kernel.num_args):
        qualifier = kernel.get_arg_info(i, cl.kernel_arg_info.ADDRESS_QUALIFIER)
        name = kernel.get_arg_info(i, cl.kernel_arg_info.TYPE_NAME).strip()
        out.append(_SCALARS.get(name) if qualifier == private and not name.endswith("*") else None)
    return out


class Program:
    """A built program and its kernels, fetched once (``program.kernels[name]``)."""

    def __init__(self, program: cl.Program, stem: str, options: tuple[str, ...], log: str = ""):
        self.program, self.stem, self.options, self.log = program, stem, options, log
        self.kernels = {}
        for k in program.all_kernels():
            k.set_scalar_arg_dtypes(scalar_arg_dtypes(k))
            self.kernels[k.function_name] = k

    def __getattr__(self, name):
        try:
            return self.__dict__["kernels"][name]
        except KeyError:
            raise AttributeError(f"{self.stem}.cl has no kernel {name!r}") from None


# PoCL's compiler writes its diagnostic summary ("4 warnings generated.")
# straight to the process' stderr, not to the build log: a build redirects
# file descriptor 2 for its duration and keeps what it caught with the log.
# One build at a time (PoCL serialises its compiler anyway).
_build_lock = threading.Lock()


@contextmanager
def _captured_fd2(sink: list):
    try:
        if sys.stderr is not None:
            sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable stderr (embedded interpreters): nothing to catch
        yield
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            try:
                if sys.stderr is not None:
                    sys.stderr.flush()
            except (OSError, ValueError):
                pass
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            sink.append(tmp.read().decode(errors="replace"))


# Work-items ahead whose path a listed kernel asks the cache for
# (kernels/prefetch.h): 2 to 8 measured alike in Sponza's listed pass.
PREFETCH_AHEAD = 4


class ProgramCache:
    def __init__(self, ctx: cl.Context):
        self.ctx = ctx
        self.dir = kernel_dir()
        self._programs: dict[tuple, Program] = {}
        self.exact_divide = correctly_rounded_divide_sqrt(ctx.devices[0])
        # kernels/prefetch.h: software prefetch of listed paths on CPU
        # devices (clang's builtin; a GPU hides the latency with other warps)
        self.prefetch_ahead = PREFETCH_AHEAD if ctx.devices[0].type & cl.device_type.CPU else 0

    def get(self, stem: str, **defines) -> Program:
        key = (stem, tuple(sorted(defines.items())))
        prog = self._programs.get(key)
        if prog is None:
            prog = self._build(stem, key[1])
            self._programs[key] = prog
        return prog

    def built(self) -> list[Program]:
        """The programs built so far."""
        return list(self._programs.values())

    def options(self, defines) -> list[str]:
        # Denormals flushed to zero: integers kept in float lanes (a segment's
        # triangle id, a point's triangle) are denormal floats, and x86 cores
        # take a microcode assist on every denormal operand; vectorised code
        # touches those lanes, which made the segment scans ~1.8x slower.
        # Every program is built the same way, so results stay comparable bit
        # for bit across kernels; no quantity oclgi computes is near 1e-38.
        # Argument info lets the cache declare each kernel's scalar types.
        options = ["-I", str(self.dir), "-cl-denorms-are-zero", "-cl-kernel-arg-info"]
        # Correctly rounded float division and sqrt wherever the device offers
        # them: OpenCL lets x / y be 2.5 ulp off by default, and GPU drivers
        # take that licence (NVIDIA's p / p is not always 1), so two kernels
        # that must agree bit for bit (light reuse at one position and the
        # ordinary run) would differ in the last place. CPU runtimes divide
        # exactly anyway: the flag changes nothing there.
        if self.exact_divide:
            options.append("-cl-fp32-correctly-rounded-divide-sqrt")
        defines = dict(defines)
        defines.setdefault("prefetch_ahead", self.prefetch_ahead)  # a program may ask for another (measuring)
        for name, value in build_defines(defines):  # the shared constants, then the program's own
            options.append(f"-DOCLGI_{name.upper()}={int(value) if isinstance(value, bool) else value}")
        return options

    def _build(self, stem: str, defines) -> Program:
        path = self.dir / f"{stem}.cl"
        if not path.is_file():
            raise OclgiError(f"kernel file {stem}.cl is missing from {self.dir}")
        options = self.options(defines)
        source = path.read_text()
        caught: list[str] = []
        failure = None
        with _build_lock, warnings.catch_warnings():
            # pyopencl warns about any non-empty build log; the log is kept here instead.
            warnings.simplefilter("ignore", cl.CompilerWarning)
            with _captured_fd2(caught):
                try:
                    program = cl.Program(self.ctx, source).build(options=options)
                except cl.RuntimeError as exc:
                    failure = exc
        compiler_text = "".join(caught).strip()
        if failure is not None:
            log = _SOURCE_NAME.sub(path.name, "\n".join(t for t in (str(failure), compiler_text) if t.strip()))
            if compiler_output_wanted():
                _show_log(path.name, options, log)
            check_cache_dir()  # an unwritable kernel cache fails builds without a compiler error
            raise KernelBuildError(f"kernel {path.name} does not build: {_first_error(log)} "
                                   f"({COMPILER_OUTPUT_ENV}=1 shows the compiler's log)", log) from None
        log = _SOURCE_NAME.sub(path.name, "\n".join(t for t in (_program_log(program), compiler_text) if t.strip()))
        if log and compiler_output_wanted():
            _show_log(path.name, options, log)
        return Program(program, stem, tuple(options), log)


def _show_log(name: str, options, log: str) -> None:
    defines = " ".join(o for o in options if o.startswith("-D")) or "no defines"
    print(f"oclgi: compiler output for {name} ({defines}):\n{log}", file=sys.stderr)


def _program_log(program: cl.Program) -> str:
    logs = (program.get_build_info(dev, cl.program_build_info.LOG) for dev in program.get_info(cl.program_info.DEVICES))
    return "\n".join(log.strip() for log in logs if log and log.strip())


_caches: dict[tuple, ProgramCache] = {}
_caches_lock = threading.Lock()


def programs(ctx: cl.Context) -> ProgramCache:
    """The program cache of a context (one per context and kernel folder,
    shared by all users)."""
    # queue.context is a new Python object for the same context: compare
    # contexts with ==, never `is`. The cache holds its context, so the
    # pointer cannot be reused by another context while it lives.
    key = (ctx.int_ptr, kernel_dir())
    with _caches_lock:
        cache = _caches.get(key)
        if cache is None or cache.ctx != ctx:
            cache = ProgramCache(ctx)
            _caches[key] = cache
    return cache
# A fixed work-group size for launches that do not ask for one. Left to
# itself, the runtime picks a size from the global size, and PoCL compiles a
# kernel anew for every work-group size it meets (about 0.4 s each): an
# interactive loop whose launch sizes vary from call to call would compile
# every frame. Results never depend on the size (fixed-point sums).
DEFAULT_LOCAL_SIZE = 64
_local_limits: dict = {}


def _local_size_for(queue: cl.CommandQueue, kernel: cl.Kernel) -> int:
    key = (kernel.int_ptr, queue.device.int_ptr)
    size = _local_limits.get(key)
    if size is None:
        limit = kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, queue.device)
        size = _local_limits[key] = max(1, min(DEFAULT_LOCAL_SIZE, limit))
    return size


# Kernels run in slices, each waited for: Python handles a signal (Ctrl-C)
# only between two calls into the OpenCL runtime, so one long launch would
# hold a Ctrl-C for its whole duration (seconds, unbounded for big batches).
# A slice is sized from the previous one's time to take about SLICE_SECONDS;
# a launch that fits in one slice stays one launch, asynchronous, as small
# launches (an interactive session's) must. Slicing by work-item offset
# changes nothing in the results: every kernel indexes its work by
# get_global_id alone (no group ids, global sizes or local memory) and its
# sums are integer (fixed point), whatever the order.
SLICE_SECONDS = 0.1
FIRST_SLICE_ITEMS = 1 << 14  # a kernel's first slice, before any is timed
_slice_items: dict = {}  # (kernel or caller's key, device) -> items of a SLICE_SECONDS slice


def _next_slice(items: int, elapsed: float, unit: int) -> int:
    """The size of the next slice after one of ``items`` took ``elapsed`` s:
    scaled to SLICE_SECONDS, at most 4x larger (a cheap first slice says
    little), a multiple of ``unit``."""
    want = items * SLICE_SECONDS / max(elapsed, 1e-6)
    want = min(want, 4.0 * items)
    return max(unit, int(want) // unit * unit)


def timed_slices(queue: cl.CommandQueue, key, total: int, unit: int = 1, first: int = FIRST_SLICE_ITEMS):
    """(start, count) pieces of ``range(total)``; the caller enqueues each
    piece's work, this waits for it before the next (the moment a Ctrl-C is
    seen) and sizes the next to take about SLICE_SECONDS. Counts are
    multiples of ``unit`` but the last. ``key`` names what is sliced (its
    slice size is remembered for its next run)."""
    key = (key, queue.device.int_ptr)
    step = _slice_items.get(key) or first
    step = max(unit, step // unit * unit)  # a size learned with another unit (work-group size) is rounded
    queue.finish()  # the first piece's time must not include earlier work
    start = 0
    while start < total:
        count = min(step, total - start)
        t0 = time.perf_counter()
        yield start, count
        queue.finish()
        start += count
        if count == step:
            step = _slice_items[key] = _next_slice(count, time.perf_counter() - t0, unit)


def read_buffer(queue: cl.CommandQueue, buf: cl.Buffer, shape, dtype) -> np.ndarray:
    """A new host array of ``shape`` and ``dtype`` holding ``buf``'s bytes (waits for them)."""
    out = np.empty(shape, dtype)
    cl.enqueue_copy(queue, out, buf)
    return out


def launch(queue: cl.CommandQueue, kernel: cl.Kernel, n: int, *args, local_size: int | None = None):
    """Run ``kernel`` over ``n`` work-items (kernels guard ``i >= n``).

    The global size is rounded up to a multiple of the work-group size:
    ``local_size``, else DEFAULT_LOCAL_SIZE (or less, if the kernel allows
    less). Results never depend on it (fixed-point sums). A launch longer
    than SLICE_SECONDS runs in slices (see above) and returns when done;
    a shorter one returns at once.
    """
    if n <= 0:
        return None
    local = local_size or _local_size_for(queue, kernel)
    gsize = (n + local - 1) // local * local
    key = (kernel.int_ptr, queue.device.int_ptr)
    if gsize <= _slice_items.get(key, FIRST_SLICE_ITEMS):
        return kernel(queue, (gsize,), (local,), *args)
    kernel.set_args(*args)
    event = None
    for start, count in timed_slices(queue, kernel.int_ptr, gsize, local):
        event = cl.enqueue_nd_range_kernel(queue, kernel, (count,), (local,), global_work_offset=(start,))
    return event
