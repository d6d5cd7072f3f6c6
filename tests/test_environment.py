"""Environment problems are one line naming their cause: the variables that
hide the OpenCL devices (OCL_ICD_VENDORS, POCL_DEVICES), an unusable
POCL_CACHE_DIR, and kernels under OCLGI_KERNEL_DIR that do not build
(a syntax error, a missing file, a broken include).

Commands run in subprocesses with the variable set, as a user would.
"""

import shutil

import pytest
from cli_run import run
from conftest import ROOT
from test_signals import _env

BOX = ROOT / "scenes" / "cornell_box.toml"
RENDER = ("render", BOX, "--photons", 2000, "--width", 8, "--height", 8, "--plain", "--quiet")  # the build's, not the estimate's


def _run(cwd, *args, **env):
    return run(cwd, *args, env=_env(**{k: str(v) for k, v in env.items()}))


def _one_line(res, status):
    assert res.returncode == status, res.stderr
    assert res.stderr.startswith("oclgi: error: ") and res.stderr.count("\n") == 1, res.stderr
    assert "Traceback" not in res.stderr
    return res.stderr


@pytest.mark.parametrize("command", ["render", "info"])
def test_an_empty_icd_vendor_folder_is_named(tmp_path, command):
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    args = (*RENDER, "-o", tmp_path / "a.exr") if command == "render" else ("info",)
    err = _one_line(_run(tmp_path, *args, OCL_ICD_VENDORS=vendors), 2)
    assert f"OCL_ICD_VENDORS={vendors} is set" in err and not (tmp_path / "a.exr").exists()


def test_pocl_devices_that_match_nothing_are_named(tmp_path):
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", POCL_DEVICES="foo"), 2)
    assert "no OpenCL device found (POCL_DEVICES=foo is set" in err


def test_the_install_hint_follows_the_variable(tmp_path):
    # The variable may not be the cause: a missing runtime is still named.
    assert "install an OpenCL runtime" in _one_line(_run(tmp_path, "info", OCL_ICD_VENDORS=tmp_path), 2)


@pytest.mark.parametrize("cache", ["/dev/null", "file", "file/sub"])
def test_an_unusable_kernel_cache_is_named(tmp_path, cache):
    (tmp_path / "file").write_text("not a folder")
    value = cache if cache.startswith("/") else str(tmp_path / cache)
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", POCL_CACHE_DIR=value), 2)
    assert f"POCL_CACHE_DIR={value} cannot hold PoCL's compiled kernels" in err
    assert not (tmp_path / "a.exr").exists()


def test_a_missing_kernel_cache_folder_is_made(tmp_path):
    cache = tmp_path / "new" / "cache"
    res = _run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", POCL_CACHE_DIR=cache)
    assert res.returncode == 0, res.stderr
    assert cache.is_dir()


@pytest.fixture
def kernels(tmp_path):
    """A copy of the kernel folder to break."""
    return shutil.copytree(ROOT / "kernels", tmp_path / "kernels")


def test_a_kernel_syntax_error_is_one_line_naming_the_file(tmp_path, kernels):
    with open(kernels / "camera.cl", "a") as f:
        f.write("\nint broken = ;\n")
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", OCLGI_KERNEL_DIR=kernels), 1)
    assert err.startswith("oclgi: error: kernel camera.cl does not build: camera.cl:")


def test_a_broken_include_is_one_line_naming_the_header(tmp_path, kernels):
    with open(kernels / "geometry.h", "a") as f:
        f.write('\n#include "nothere.h"\n')
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", OCLGI_KERNEL_DIR=kernels), 1)
    assert "does not build" in err and "geometry.h" in err and "'nothere.h' file not found" in err


def test_a_missing_kernel_file_is_one_line(tmp_path, kernels):
    (kernels / "camera.cl").unlink()
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", OCLGI_KERNEL_DIR=kernels), 2)
    assert err == f"oclgi: error: kernel file camera.cl is missing from {kernels}\n"


def test_a_missing_kernel_folder_is_one_line(tmp_path):
    err = _one_line(_run(tmp_path, *RENDER, "-o", tmp_path / "a.exr", OCLGI_KERNEL_DIR=tmp_path / "none"), 2)
    assert "is missing from" in err and str(tmp_path / "none") in err
