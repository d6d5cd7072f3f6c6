"""Jobs too large for the device or the host are refused before any work,
with the estimate (oclgi/budget.py); a long run says how long up front.

The device's and the host's limits are monkeypatched (``budget.device_limits``,
``budget.host_available``), so each refusal is cheap and does not depend on
the machine. Before these checks: ``render --width 16384 --height 16384``
ended in a pyopencl INVALID_BUFFER_SIZE traceback, ``study --seeds 1e9`` and
``--points random:2e8`` grew past 14 GiB before any check, ``animate
--frames 1e8`` built poses for minutes, and 2^31 photons started with no
word of the time they would take.
"""

import functools
import re
import warnings

import numpy as np
import pytest
from small_scene import write_scene

import oclgi
from oclgi import budget
from oclgi.errors import OclgiError

GIB = 1 << 30
XYZN = np.array([[0.1, 0.0, 0.2, 0, 1, 0], [-0.3, 0.0, 0.1, 0, 1, 0]], float)


@pytest.fixture
def scene(tmp_path):
    return write_scene(tmp_path, radius="0.2")


@pytest.fixture(scope="module")
def engine(tmp_path_factory):
    return oclgi.Engine(oclgi.load_file(write_scene(tmp_path_factory.mktemp("resources"), radius="0.2")),
                        progress=False)


@pytest.fixture
def device(monkeypatch):
    """A device with memory of its own (a GPU) that allows ``one`` bytes in a
    buffer and ``total`` in all; a roomy host."""
    def limit(one, total):
        monkeypatch.setattr(budget, "device_limits", lambda dev: (one, total))
        monkeypatch.setattr(budget, "shares_host_memory", lambda dev: False)
        monkeypatch.setattr(budget, "host_available", lambda: 1 << 50)

    return limit


@pytest.fixture
def host(monkeypatch):
    """A host with ``nbytes`` available; a roomy device."""
    def limit(nbytes):
        monkeypatch.setattr(budget, "host_available", lambda: nbytes)
        monkeypatch.setattr(budget, "device_limits", lambda dev: (1 << 50, 1 << 50))

    return limit


@pytest.fixture
def cli(cli_fails):
    """``oclgi.cli.main`` in the scene's folder: exit 2, one error line, no file; returns the line."""
    return functools.partial(cli_fails, alone=True)


# -- the device ------------------------------------------------------------------------------


def test_huge_image_refused_with_its_estimate(scene, device, cli):
    """Was a pyopencl INVALID_BUFFER_SIZE traceback after the camera had run."""
    device(int(9.8 * GIB), int(23.4 * GIB))
    line = cli(scene.parent, "render", "s.toml", "--method", "detp", "--width", "16384", "--height", "16384",
               "--plain", "-o", "x.png")
    m = re.fullmatch(r"oclgi: error: a 16384x16384 image needs about ([\d.]+) GiB of device memory, ([\d.]+) GiB in "
                     r"its largest buffer \(sums\) \(the device allows 9.8 GiB in one buffer, 23.4 GiB in all\); "
                     r"use a smaller width/height", line)
    assert m, line
    pixels = 16384**2
    assert float(m.group(2)) == round(pixels * 24 / GIB, 1)  # the int64 RGB sums, one per pixel
    assert pixels * 100 / GIB < float(m.group(1)) < pixels * 200 / GIB


def test_one_buffer_too_large_is_enough_to_refuse(engine, device):
    n = 64 * 64  # 96 KiB of sums, more than the 75 KiB of 100 paths' segments
    device(n * 24 - 1, 1 << 50)  # everything fits but the sums' buffer
    with pytest.raises(OclgiError, match=r"^a 64x64 image needs about 571.4 KiB of device memory, 96.0 KiB in its "
                                         r"largest buffer \(sums\) \(the device allows 96.0 KiB in one buffer"):
        engine.render(width=64, height=64, photons=100, method="detp")
    device(n * 24, 1 << 50)
    assert engine.render(width=64, height=64, photons=100, method="detp").radiance.shape == (64, 64, 3)


def test_points_refused_on_a_small_device(engine, device):
    points = np.tile(XYZN, (500, 1))
    device(1 << 50, 500 * 2 * 40)  # not even 40 bytes a point in all
    for method in ("detp", "impact", "photon_map"):
        with pytest.raises(OclgiError, match=r"^an estimate at 1,000 points needs about [\d.]+ [KM]iB of device memory"):
            engine.irradiance(points, method=method, photons=1000)
    with pytest.raises(OclgiError, match=r"^the visible points of a 64x64 camera needs about"):
        engine.camera_points(width=64, height=64)


def test_cpu_device_total_is_the_hosts_memory(engine, monkeypatch):
    """On a CPU device the buffers are host memory: a job past the device's
    stated global memory runs when the host has room (PoCL's 8192x8192
    render did), and is refused by the host's memory when it has not."""
    points = np.tile(XYZN, (500, 1))
    monkeypatch.setattr(budget, "device_limits", lambda dev: (1 << 50, 500 * 2 * 40))
    monkeypatch.setattr(budget, "shares_host_memory", lambda dev: True)
    monkeypatch.setattr(budget, "host_available", lambda: 1 << 50)
    assert engine.irradiance(points, method="detp", photons=1000).irradiance.shape == (1000, 3)
    monkeypatch.setattr(budget, "host_available", lambda: 500 * 2 * 40)
    with pytest.raises(OclgiError, match=r"^an estimate at 1,000 points needs about [\d.]+ [KM]iB of host memory"):
        engine.irradiance(points, method="detp", photons=1000)


def test_photon_maps_count_their_neighbour_lists(engine, device):
    device(1000 * 4 * 4000, 1 << 50)  # the k ids of 1,000 points fit for k < 4,000
    points = np.tile(XYZN, (500, 1))
    with pytest.raises(OclgiError, match=r"largest buffer \(neighbour ids\)"):
        engine.irradiance(points, method="photon_map", photons=1000, k=4096)
    assert engine.irradiance(points, method="photon_map", photons=1000, k=20).irradiance.shape == (1000, 3)


# -- the host ---------------------------------------------------------------------------------


def test_study_seeds_refused_before_their_list(scene, host, cli):
    """--seeds 1e9 grew a list of a billion seeds first."""
    host(GIB)
    line = cli(scene.parent, "study", "s.toml", "--seeds", "1e9", "--points", "random:4", "-o", "out")
    assert line == ("oclgi: error: a study of 1,000,000,000 seeds needs about 37.3 GiB of host memory "
                    "(1.0 GiB is available); use fewer seeds")


def test_study_points_refused_before_they_are_drawn(scene, host, cli):
    """--points random:2e8 drew 200 million points (past 14 GiB) first."""
    host(4 * GIB)
    line = cli(scene.parent, "study", "s.toml", "--seeds", "2", "--photons", "1000", "--points", "random:2e8",
               "-o", "out")
    assert re.fullmatch(r"oclgi: error: a study of 3 configurations x 2 seeds at 200,000,000 points needs about "
                        r"[\d.]+ GiB of host memory \(4.0 GiB is available\); use fewer seeds, points or photon counts",
                        line), line


def test_study_api_refuses_alike(engine, host):
    from oclgi.study import Config, run_study

    host(GIB)
    with pytest.raises(OclgiError, match=r"^a study of 1,000,000,000 seeds needs about 37.3 GiB of host memory"):
        run_study(engine, [Config("detp", [1000])], points="random:4", seeds=10**9)
    with pytest.raises(OclgiError, match=r"^a study of 2 configurations x 8 seeds at 4,000,000 points needs about"):
        run_study(engine, [Config("detp", [1000, 2000])], points="random:4e6")
    with pytest.raises(OclgiError, match=r"^a study of 1 configurations x 2 seeds at 16,000,000 points"):
        run_study(engine, [Config("detp", [1000])], points="camera:4000x4000", seeds=2)
    with pytest.raises(OclgiError, match=r"^seeds must be a count \(an integer, at least 2\) or a list"):
        run_study(engine, [Config("detp", [1000])], points="random:4", seeds=2.5)


def test_random_points_refused_on_a_small_host(engine, host):
    from oclgi.study.run import study_points

    host(100 << 20)
    with pytest.raises(OclgiError, match=r"^1,000,000 random points needs about 244.1 MiB of host memory \(100.0 MiB is available\)"):
        study_points(engine, "random:1e6")
    assert len(study_points(engine, "random:1e3")) == 1000


def test_cpu_device_buffers_count_against_the_host(engine, monkeypatch):
    """A CPU device's buffers are the host's memory."""
    monkeypatch.setattr(budget, "device_limits", lambda dev: (1 << 50, 1 << 50))
    monkeypatch.setattr(budget, "host_available", lambda: 1000 * 200)
    monkeypatch.setattr(budget, "shares_host_memory", lambda dev: True)
    points = np.tile(XYZN, (500, 1))
    with pytest.raises(OclgiError, match=r"^an estimate at 1,000 points needs about [\d.]+ KiB of host memory"):
        engine.irradiance(points, method="detp", photons=1000)
    monkeypatch.setattr(budget, "shares_host_memory", lambda dev: False)
    assert engine.irradiance(points, method="detp", photons=1000).irradiance.shape == (1000, 3)


def test_animation_frames_capped_with_the_estimate(scene, cli):
    """--frames 1e8 built a hundred million poses (minutes, gigabytes) before any check."""
    line = cli(scene.parent, "animate", "s.toml", "--path", "line:0.1,0,0", "--frames", "1e8", "-o", "out")
    assert line == ("oclgi: error: argument --frames: expected an integer in 1..1,000,000, got 100000000 "
                    "(its poses and timings alone would take about 119.2 GiB of memory) (see `oclgi animate --help`)")
    line = cli(scene.parent, "animate", "s.toml", "--path", "line:0.1,0,0", "--frames", "0", "-o", "out")
    assert "argument --frames: expected an integer in 1..1,000,000, got 0" in line


# -- time -----------------------------------------------------------------------------------------


def test_long_run_gives_a_time_estimate(scene, monkeypatch):
    """2^31 photons started with no word of how long they would take."""
    monkeypatch.setattr(budget, "NOTICE_SECONDS", 0.0)  # any run of several batches is "long"
    engine = oclgi.Engine(oclgi.load_file(scene), progress=False, batch_bytes=1 << 16)
    batch = (1 << 16) // (16 * 48)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        engine.irradiance(XYZN, photons=10 * batch)
    notes = [str(w.message) for w in caught if issubclass(w.category, oclgi.OclgiWarning)]
    assert len(notes) == 1, notes
    assert re.fullmatch(rf"{10 * batch:,} photon paths will take about \d+ (seconds|minutes|hours|days) on this device \(from the first "
                        rf"{batch:,} in [\d.]+s\); use fewer photons for a quicker run", notes[0]), notes[0]
    with warnings.catch_warnings(record=True) as caught:  # one batch: nothing to extrapolate
        warnings.simplefilter("always")
        engine.irradiance(XYZN, photons=batch)
    assert not [w for w in caught if issubclass(w.category, oclgi.OclgiWarning)]


def test_time_notice_wording():
    assert budget.time_notice(1000, 1.0, 2**31) == (
        "2,147,483,648 photon paths will take about 25 days on this device (from the first 1,000 in 1.0s); "
        "use fewer photons for a quicker run")
    assert budget.time_notice(1000, 1.0, 10_000) is None  # 10 s
    assert budget.duration(150) == "2 minutes" and budget.duration(7200) == "2 hours"


def test_real_limits_are_read():
    from oclgi.cl.device import create_context

    _, queue = create_context()
    one, total = budget.device_limits(queue.device)
    assert 0 < one <= total
    assert budget.host_available() > 0


def test_an_impact_count_render_past_the_hosts_memory_is_refused_first(engine, monkeypatch):
    """An 8192x8192 Impact Count render on a CPU device peaked at 14.6 GiB
    (bench/README.md): its estimate (device and host together, 14.8 GiB)
    holds the peak, and a host with less available refuses it before any
    work; with the estimate available it would run."""
    monkeypatch.setattr(budget, "device_limits", lambda dev: (1 << 50, 1 << 50))
    monkeypatch.setattr(budget, "shares_host_memory", lambda dev: True)
    need = budget.render_need(8192, 8192, "impact", 1000, 10, engine.batch_bytes)
    assert need.device_total + need.host >= 14.6 * GIB  # the measured peak
    monkeypatch.setattr(budget, "host_available", lambda: 12 * GIB)
    with pytest.raises(OclgiError, match=r"^a 8192x8192 image needs about [\d.]+ GiB of host memory \(12.0 GiB is "
                                         r"available\); use a smaller width/height"):
        engine.render(width=8192, height=8192, method="impact", photons=1000)
