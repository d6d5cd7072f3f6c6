"""Shared fixtures. Tests run on the default OpenCL device (PoCL's CPU
device in CI); a missing device fails the run, it never skips.

The suite compiles every kernel cold, as a fresh machine does: PoCL gets a
private, empty kernel cache for the session (subprocesses inherit it) and
pyopencl's binary cache is off, so no result depends on what this machine
compiled before. ``OCLGI_TEST_POCL_CACHE=DIR`` keeps a cache between runs
instead, for quick local iterations; CI never sets it.
"""

import atexit
import functools
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest


_SESSION_CACHE = "OCLGI_TEST_SESSION_POCL_CACHE"


def _private_kernel_cache() -> None:
    # Before anything imports pyopencl: PoCL reads its variables when the
    # platform is first opened.
    keep = os.environ.get("OCLGI_TEST_POCL_CACHE")
    if keep:
        os.environ["POCL_CACHE_DIR"] = keep
    elif os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get(_SESSION_CACHE):
        # a pytest-xdist worker: the run's one cache, made (and removed) by the controller
        os.environ["POCL_CACHE_DIR"] = os.environ[_SESSION_CACHE]
    else:
        cache = tempfile.mkdtemp(prefix="oclgi-test-pocl-cache-")
        os.environ["POCL_CACHE_DIR"] = os.environ[_SESSION_CACHE] = cache
        atexit.register(shutil.rmtree, cache, ignore_errors=True)
    os.environ["PYOPENCL_NO_CACHE"] = "1"

    os.environ.pop("OCLGI_COMPILER_OUTPUT", None)  # tests see what a user sees by default


_private_kernel_cache()

def pytest_addoption(parser):
    parser.addoption("--full", action="store_true",
                     help="also run the long campaigns (tests marked full): `make test-full`")


# The files whose tests take longest (tens of seconds each on 2 cores) run
# first: pytest-xdist hands files to workers in order, and one of these
# started last would leave a worker alone with it at the end.
FIRST = ("test_warm", "test_viewer_browser", "test_distributed", "test_signals", "test_checkpoint",
         "test_kernel_build", "test_detp_sphere_cache", "test_environment")


def pytest_collection_modifyitems(config, items):
    """Tests marked ``full`` (long campaigns: README.md, Tests) run only
    with ``--full``; without it they are deselected, and the summary counts
    them. The longest files go first (``FIRST``), each file's tests in their
    own order."""
    rank = {name: i for i, name in enumerate(FIRST)}
    items.sort(key=lambda item: rank.get(item.module.__name__, len(FIRST)))  # stable: the rest keep their order
    if config.getoption("--full"):
        return
    dropped = [item for item in items if item.get_closest_marker("full")]
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = [item for item in items if not item.get_closest_marker("full")]


ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"


@pytest.fixture(scope="session")
def cl_env():
    from oclgi.cl.device import create_context

    return create_context()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def scenes_dir():
    return SCENES


@pytest.fixture
def cli_fails(monkeypatch, capsys):
    """``cli_fails(cwd, *args, match=None, alone=False, sub=False)``: ``oclgi
    ARGS`` in ``cwd``, in-process (``sub``: in a subprocess), fails cleanly
    (cli_run.fails_cleanly); returns the error line."""
    from cli_run import fails_cleanly, in_process, run

    def inproc(cwd, *args):
        return in_process(monkeypatch, capsys, cwd, *args)

    return lambda cwd, *args, sub=False, **kw: fails_cleanly(run if sub else inproc, cwd, *args, **kw)


@pytest.fixture(scope="session")
def plane():
    """The point light over a 16 x 16 cell black plane (analytic_scenes.py)."""
    import oclgi
    from analytic_scenes import plane_scene

    return oclgi.Engine(plane_scene(n_cells=16, half=4.0))


# -- shared by the accelerated-DETP tests: scenes, points, plain DETP's sums --

@pytest.fixture(scope="session")
def cornell(scenes_dir):
    """The Cornell box (scenes/cornell_box.toml), one engine for the session."""
    from exactness import cornell_engine

    return cornell_engine(scenes_dir)


@pytest.fixture(scope="session")
def engines(cornell, scenes_dir):
    """The Cornell box and the bunny in a box (tests/exactness.py)."""
    from exactness import bunny_engine

    return {"cornell": cornell, "bunny": bunny_engine(scenes_dir)}


@pytest.fixture(scope="session")
def points(engines):
    """1,500 random surface points per scene."""
    from exactness import surface_points

    rng = np.random.default_rng(2024)
    return {name: surface_points(e, 1500, rng) for name, e in engines.items()}


@pytest.fixture(scope="session")
def plain(engines, points):
    """Plain DETP's accumulators, computed once per (scene, fraction, count_emitted)."""
    @functools.cache
    def get(scene, frac, count_emitted=True):
        from exactness import DETP_PHOTONS

        e = engines[scene]
        est = e.irradiance(points[scene], method="detp", radius=frac * e.scene.diagonal,
                           photons=DETP_PHOTONS, count_emitted=count_emitted)
        assert est.accumulators.any(), "the test must select some segments"
        return est.accumulators

    return get


@pytest.fixture
def same_as_plain(engines, points, plain, request):
    """``same_as_plain(scene, frac, count_emitted=True, engine=None, **options)``:
    the test module's ``METHOD`` equals plain DETP (exactness.check_variant_same_as_plain)."""
    from exactness import check_variant_same_as_plain

    return functools.partial(check_variant_same_as_plain, engines, points, plain, request.module.METHOD)
