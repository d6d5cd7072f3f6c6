"""The one program cache: every `.cl` file under ``kernels/`` is built here.

Each (file stem, define set) is built once per context, with ``-I`` on the
kernel folder (shared headers) and pyopencl's include folder (Random123's
Philox), and ``-cl-denorms-are-zero`` (see ``_build``). Kernel handles are fetched once per built program, never per call.
PoCL keeps its own binary cache keyed on the preprocessed source, so editing a
header rebuilds what includes it.

The kernel folder is found as ``OCLGI_KERNEL_DIR`` if set, else as the
``oclgi.kernels`` package (an installed copy ships the ``.cl`` and ``.h``
files there; in the source tree it maps to ``kernels/``).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

import pyopencl as cl

from ..errors import OclgiError


def kernel_dir() -> Path:
    env = os.environ.get("OCLGI_KERNEL_DIR")
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


class Program:
    """A built program and its kernels, fetched once (``program.kernels[name]``)."""

    def __init__(self, program: cl.Program, stem: str, options: tuple[str, ...]):
        self.program = program
        self.stem = stem
        self.options = options
        self.kernels = {k.function_name: k for k in program.all_kernels()}

    def __getattr__(self, name):
        try:
            return self.__dict__["kernels"][name]
        except KeyError:
            raise AttributeError(f"{self.stem}.cl has no kernel {name!r}") from None


class ProgramCache:
    def __init__(self, ctx: cl.Context):
        self.ctx = ctx
        self.dir = kernel_dir()
        self._programs: dict[tuple, Program] = {}

    def get(self, stem: str, **defines) -> Program:
        key = (stem, tuple(sorted(defines.items())))
        prog = self._programs.get(key)
        if prog is None:
            prog = self._build(stem, key[1])
            self._programs[key] = prog
        return prog

    def _build(self, stem: str, defines) -> Program:
        path = self.dir / f"{stem}.cl"
        if not path.is_file():
            raise OclgiError(f"kernel file {stem}.cl is missing from {self.dir}")
        # Denormals flushed to zero: integers kept in float lanes (a segment's
        # triangle id, a point's triangle) are denormal floats, and x86 cores
        # take a microcode assist on every denormal operand; vectorised code
        # touches those lanes, which made the segment scans ~1.8x slower.
        # Every program is built the same way, so results stay comparable bit
        # for bit across kernels; no quantity oclgi computes is near 1e-38.
        options = ["-I", str(self.dir), "-cl-denorms-are-zero"]
        for name, value in defines:
            options.append(f"-DOCLGI_{name.upper()}={int(value) if isinstance(value, bool) else value}")
        source = path.read_text()
        try:
            program = cl.Program(self.ctx, source).build(options=options)
        except cl.RuntimeError as exc:  # build failure: keep the compiler log
            raise RuntimeError(f"building {path.name} with {options} failed:\n{exc}") from exc
        return Program(program, stem, tuple(options))


_caches: dict[int, ProgramCache] = {}


def programs(ctx: cl.Context) -> ProgramCache:
    """The program cache of a context (one per context, shared by all users)."""
    # queue.context is a new Python object for the same context: compare
    # contexts with ==, never `is`. The cache holds its context, so the
    # pointer cannot be reused by another context while it lives.
    cache = _caches.get(ctx.int_ptr)
    if cache is None or cache.ctx != ctx:
        cache = ProgramCache(ctx)
        _caches[ctx.int_ptr] = cache
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


def launch(queue: cl.CommandQueue, kernel: cl.Kernel, n: int, *args, local_size: int | None = None):
    """Run ``kernel`` over ``n`` work-items (kernels guard ``i >= n``).

    The global size is rounded up to a multiple of the work-group size:
    ``local_size``, else DEFAULT_LOCAL_SIZE (or less, if the kernel allows
    less). Results never depend on it (fixed-point sums).
    """
    if n <= 0:
        return None
    local = local_size or _local_size_for(queue, kernel)
    gsize = (n + local - 1) // local * local
    return kernel(queue, (gsize,), (local,), *args)
