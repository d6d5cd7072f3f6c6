"""Every kernel builds without a compiler warning, on this machine's device
and for both x86 CPU targets oclgi runs on; compiler output stays off the
terminal unless asked for; a broken kernel gives one clear line.

PoCL picks its code generation target from the CPU it runs on (Debian's
``POCL_KERNELLIB_NAME`` can only step down to a subset of the CPU's own
features), so one machine cannot build for AVX-512 through PoCL when it
lacks AVX-512. The target check therefore runs the compiler PoCL itself is
built on (Debian's PoCL depends on clang-15) with ``-march=haswell`` (AVX2,
PoCL's ``pthread-haswell``) and ``-march=skylake-avx512``, on the same files
with the same options, which is where target-dependent warnings (a wide
vector passed by value through a function, say) come from.
"""

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

from cli_run import run
from oclgi.cl.programs import PREFETCH_AHEAD, KernelBuildError, ProgramCache, kernel_dir, programs

TARGETS = ("haswell", "skylake-avx512")
VARIANTS = ({}, {"count_work": 1})


def _kernel_files():
    return sorted(kernel_dir().glob("*.cl"))


def _clang():
    for name in ("clang-15", "clang"):
        path = shutil.which(name)
        if path:
            return path
    pytest.fail("no clang found: the CPU-target check needs the compiler PoCL is built on "
                "(Debian's pocl-opencl-icd brings clang-15)", pytrace=False)


def _clang_options(cache: ProgramCache, defines: dict) -> list[str]:
    """The program cache's options in clang's spelling (as PoCL passes them)."""
    out = []
    for opt in cache.options(tuple(sorted(defines.items()))):
        if opt == "-cl-denorms-are-zero":
            out.append("-fdenormal-fp-math=positive-zero")  # what PoCL turns it into for LLVM >= 11
        elif opt != "-cl-kernel-arg-info":
            out.append(opt)
    return out + ["-I", str(Path(cl.__file__).parent / "cl")]


def test_every_kernel_builds_without_warnings_on_this_device(cl_env):
    ctx, _queue = cl_env
    cache = ProgramCache(ctx)  # a fresh cache: every file is built here, not reused
    built = []
    for path in _kernel_files():
        for defines in VARIANTS:
            log = cache.get(path.stem, **defines).log
            assert "warning" not in log.lower(), f"{path.name} {defines}:\n{log}"
            built.append(path.stem)
    assert len(built) == 2 * len(_kernel_files()) >= 2 * 15


@pytest.mark.parametrize("variant", [0, pytest.param(1, marks=pytest.mark.full)])
@pytest.mark.parametrize("target", TARGETS)
def test_every_kernel_compiles_without_warnings_for_cpu_target(cl_env, target, variant):
    """Both targets for the kernels as runs build them; the counting build
    (``count_work``) for both targets in the full suite (it builds without a
    warning on this machine's device in every run: the test above)."""
    clang = _clang()
    cache = programs(cl_env[0])
    for path in _kernel_files():
        for defines in VARIANTS[variant:variant + 1]:
            cmd = [clang, "-x", "cl", "-cl-std=CL1.2", "-Xclang", "-finclude-default-header",
                   "-Xclang", "-cl-ext=+cl_khr_int64_base_atomics,+cl_khr_int64_extended_atomics,+cl_khr_fp64",
                   "-target", "x86_64-pc-linux-gnu", f"-march={target}", *_clang_options(cache, defines),
                   "-emit-llvm", "-c", "-o", os.devnull, str(path)]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
            assert res.returncode == 0, f"{path.name} {defines} for {target}:\n{res.stderr}"
            assert "warning" not in res.stderr, f"{path.name} {defines} for {target}:\n{res.stderr}"


def test_the_target_check_sees_a_wide_vector_passed_by_value(cl_env, tmp_path):
    """The check above can fail: a long8 through a function warns for AVX2, not for AVX-512."""
    clang = _clang()
    src = tmp_path / "wide.cl"
    src.write_text("long8 twice(long8 v) { return v + v; }\n"
                   "__kernel void k(__global long *o) { vstore8(twice(vload8(0, o)), 0, o); }\n")
    said = {}
    for target in TARGETS:
        res = subprocess.run([clang, "-x", "cl", "-cl-std=CL1.2", "-Xclang", "-finclude-default-header",
                              "-target", "x86_64-pc-linux-gnu", f"-march={target}", "-emit-llvm", "-c",
                              "-o", os.devnull, str(src)], capture_output=True, text=True, timeout=60)
        said[target] = res.stderr
    assert "changes the ABI" in said["haswell"] and "warning" not in said["skylake-avx512"]


def _kernels_with(tmp_path, stem, extra):
    """A copy of the kernel folder where ``stem.cl`` has ``extra`` appended."""
    folder = tmp_path / "kernels"
    shutil.copytree(kernel_dir(), folder, ignore=shutil.ignore_patterns("__pycache__", "*.py"))
    with open(folder / f"{stem}.cl", "a") as f:
        f.write("\n" + extra + "\n")
    return folder


SMALL = ("--photons", "2000", "--width", "8", "--height", "8", "--method", "detp")


def test_compiler_output_is_kept_off_the_terminal_unless_asked(tmp_path, scenes_dir, monkeypatch):
    monkeypatch.setenv("OCLGI_KERNEL_DIR", str(_kernels_with(tmp_path, "image", '#warning "oclgi-test-warning"')))
    scene = scenes_dir / "cornell_box.toml"
    quiet = run(tmp_path, "render", scene, *SMALL, "-o", tmp_path / "a.exr")
    assert quiet.returncode == 0, quiet.stderr
    assert "warning" not in quiet.stderr and "generated" not in quiet.stderr, quiet.stderr
    loud = run(tmp_path, "render", scene, *SMALL, "-o", tmp_path / "b.exr", "--verbose")
    assert loud.returncode == 0, loud.stderr
    assert "oclgi-test-warning" in loud.stderr and "compiler output for image.cl" in loud.stderr
    monkeypatch.setenv("OCLGI_COMPILER_OUTPUT", "1")
    assert "oclgi-test-warning" in run(tmp_path, "render", scene, *SMALL, "-o", tmp_path / "c.exr").stderr


def test_a_kernel_that_does_not_build_gives_one_line(tmp_path, scenes_dir, monkeypatch):
    monkeypatch.setenv("OCLGI_KERNEL_DIR", str(_kernels_with(tmp_path, "image", "__kernel void oclgi_broken(__global int *o) { o[0] = no_such_name; }")))
    res = run(tmp_path, "render", scenes_dir / "cornell_box.toml", *SMALL, "--plain", "-o", tmp_path / "x.exr")
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("oclgi: error: kernel image.cl does not build: image.cl:")
    assert "no_such_name" in lines[0] and "Traceback" not in res.stderr
    assert not list(tmp_path.glob("x.*")) and not list(tmp_path.glob(".x.*"))


def test_build_error_from_the_api_keeps_the_log(cl_env, tmp_path, monkeypatch):
    monkeypatch.setenv("OCLGI_KERNEL_DIR", str(_kernels_with(tmp_path, "image", "__kernel void oclgi_broken(__global int *o) { o[0] = no_such_name; }")))
    with pytest.raises(KernelBuildError, match="image.cl does not build") as info:
        ProgramCache(cl_env[0]).get("image")
    assert "no_such_name" in info.value.log


def test_scalar_arguments_are_declared_once(cl_env):
    """Plain Python numbers are packed as the kernel's own types; a wrong
    argument count fails at the call, before anything runs."""
    ctx, queue = cl_env
    k = programs(ctx).get("detp").detp_resolve  # (long *acc, int n, float inv_norm, float4 *out)
    acc = np.arange(6, dtype=np.int64) * 3
    mf = cl.mem_flags
    a = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=acc)
    out = cl.Buffer(ctx, mf.WRITE_ONLY, 2 * 16)
    k(queue, (2,), None, a, 2, 0.5, out)
    got = np.empty((2, 4), np.float32)
    cl.enqueue_copy(queue, got, out)
    assert np.array_equal(got[:, :3], (acc.reshape(2, 3) * 0.5).astype(np.float32))
    with pytest.raises(TypeError):
        k(queue, (2,), None, a, 2, out)


def test_prefetch_is_on_for_cpu_devices_and_builds_off(cl_env):
    """kernels/prefetch.h: the program cache turns software prefetch on for
    a CPU device only; off, as on a GPU, the kernels that use it build
    without a warning too (on a CPU they run on, prefetching, in every
    exactness test)."""
    ctx, _queue = cl_env
    cache = ProgramCache(ctx)
    cpu = bool(ctx.devices[0].type & cl.device_type.CPU)
    assert PREFETCH_AHEAD > 0 and (f"-DOCLGI_PREFETCH_AHEAD={PREFETCH_AHEAD}" in cache.options(())) == cpu
    assert "-DOCLGI_PREFETCH_AHEAD=0" in cache.options((("prefetch_ahead", 0),))
    users = [p for p in _kernel_files() if '#include "prefetch.h"' in p.read_text()]
    assert {p.stem for p in users} >= {"update", "detp_disc_index", "photon_trace"}
    for path in users:
        log = cache.get(path.stem, prefetch_ahead=0).log
        assert "warning" not in log.lower(), f"{path.name} without prefetch:\n{log}"
