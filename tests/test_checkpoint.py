"""Checkpoints: a run killed at a random point (SIGKILL) and resumed, a run
stopped by Ctrl-C or SIGTERM and resumed, and a finished run given more
photons all equal one uninterrupted run, bit for bit (image bytes and the
integer sums); a checkpoint of another run is refused before any work.

The commands run as a user runs them (tests/cli_run.py); the uninterrupted
runs in-process, which writes the same bytes.
"""

import io
import json
import signal
import time
import zipfile

import numpy as np
import pytest
from cli_run import in_process, run
from conftest import ROOT
from test_signals import _start

import oclgi
from oclgi.checkpoint import load
from oclgi.params import METHODS
from oclgi.tracing.run import PathRange

BOX = ROOT / "scenes" / "cornell_box.toml"
# Long enough for a kill to land inside the loop (dozens of batches), small
# enough for a few seconds a run.
PHOTONS, BATCH = 400_000, 10_000
SIZE = 12


def _args(out, method, photons=PHOTONS, *extra):
    return ("render", BOX, "--method", method, "--photons", photons, "--width", SIZE, "--height", SIZE, "--batch-paths",
            BATCH, "-O", *(("k=20",) if method == "photon_map" else ("extension=0",)), "-o", out, "--quiet", *extra)


def _same_files(a, b):
    for suffix in (".exr", ".png"):
        assert a.with_suffix(suffix).read_bytes() == b.with_suffix(suffix).read_bytes(), suffix


def _same_sums(a, b):
    (_, sa), (_, sb) = load(a), load(b)
    assert sa.next_path == sb.next_path and sa.segments == sb.segments and sa.sums.keys() == sb.sums.keys()
    for k in sa.sums:
        assert sa.sums[k].tobytes() == sb.sums[k].tobytes(), k


def _wait_for(path, proc, timeout=120.0):
    t0 = time.monotonic()
    while not path.exists():
        assert proc.poll() is None, f"ended ({proc.returncode}) before its first save: {proc.stderr.read()}"
        assert time.monotonic() - t0 < timeout, "no checkpoint written"
        time.sleep(0.005)


# Killed and resumed as a user runs it: the default method and Photon Maps (a
# state of impacts, not sums) in `make test`, every other method in the full
# suite; test_run_api_resume_and_extend_equal_one_run restores every method's
# state in-process.
KILLED = [m if m in ("detp_disc_index", "photon_map") else pytest.param(m, marks=pytest.mark.full) for m in METHODS]


@pytest.mark.parametrize("method", KILLED)
def test_killed_then_resumed_equals_uninterrupted(tmp_path, method, monkeypatch, capsys):
    full = in_process(monkeypatch, capsys, tmp_path, *_args("full.exr", method), "--checkpoint", "full.npz")
    assert full.returncode == 0, full.stderr
    # Killed at a random moment of the loop: after the first save, somewhere in the dozens of batches.
    rng = np.random.default_rng(sum(map(ord, method)))
    p = _start(tmp_path, *_args("part.exr", method), "--checkpoint", "part.npz", "--checkpoint-every", "0")
    _wait_for(tmp_path / "part.npz", p)
    time.sleep(rng.uniform(0.0, 0.3))
    p.send_signal(signal.SIGKILL)
    p.communicate(timeout=60)
    assert p.returncode == -signal.SIGKILL, "the run ended before it was killed: make it longer"
    assert not (tmp_path / "part.exr").exists()
    meta, state = load(tmp_path / "part.npz")
    assert 0 < state.next_path <= PHOTONS
    res = run(tmp_path, *_args("part.exr", method), "--resume", "part.npz")
    assert res.returncode == 0, res.stderr
    _same_files(tmp_path / "full.exr", tmp_path / "part.exr")
    _same_sums(tmp_path / "full.npz", tmp_path / "part.npz")
    # no temporaries left by the kill once a later save has run
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.exr", "full.npz", "full.png", "part.exr",
                                                          "part.npz", "part.png"]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_stopped_by_a_signal_saves_and_resumes(tmp_path, signum, monkeypatch, capsys):
    method = "detp_disc_index"
    full = in_process(monkeypatch, capsys, tmp_path, *_args("full.exr", method))
    assert full.returncode == 0, full.stderr
    p = _start(tmp_path, *_args("part.exr", method), "--checkpoint", "part.npz", "--checkpoint-every", "0")
    _wait_for(tmp_path / "part.npz", p)  # the loop runs: a save after every batch
    p.send_signal(signum)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert err.strip().splitlines() == [f"oclgi: interrupted ({signal.Signals(signum).name}); the run is saved in "
                                        "part.npz: continue it with --resume part.npz"]
    assert not (tmp_path / "part.exr").exists() and out == ""
    _, state = load(tmp_path / "part.npz")
    assert 0 < state.next_path < PHOTONS and state.next_path % BATCH == 0  # whole batches only
    res = run(tmp_path, *_args("part.exr", method), "--resume", "part.npz")
    assert res.returncode == 0, res.stderr
    _same_files(tmp_path / "full.exr", tmp_path / "part.exr")


@pytest.mark.parametrize("method", ["detp_disc_index", "impact", "photon_map"])
def test_more_photons_equal_one_longer_run(tmp_path, method, monkeypatch, capsys):
    first, more = 100_000, 50_000
    cmd = lambda out, n, *extra: in_process(monkeypatch, capsys, tmp_path, *_args(out, method, n), *extra)  # noqa: E731
    assert cmd("long.exr", first + more).returncode == 0
    assert cmd("short.exr", first, "--checkpoint", "c.npz").returncode == 0
    res = cmd("more.exr", first, "--resume", "c.npz", "--more", more)
    assert res.returncode == 0, res.stderr
    _same_files(tmp_path / "long.exr", tmp_path / "more.exr")
    assert load(tmp_path / "c.npz")[0]["params"]["photons"] == first + more
    assert (tmp_path / "short.png").read_bytes() != (tmp_path / "more.png").read_bytes()
    # a resume that needs no photons changes nothing: the finished run again
    res = cmd("again.exr", first + more, "--resume", "c.npz")
    assert res.returncode == 0, res.stderr
    _same_files(tmp_path / "long.exr", tmp_path / "again.exr")


def test_resume_alone_takes_the_run_as_started(tmp_path, monkeypatch, capsys):
    """``--resume FILE`` alone (the scene and nothing else) continues a run
    started with any settings: its image size, samples, exposure, view,
    layers, output and method options come from the checkpoint, and the
    result equals one run of the sum, bit for bit. A setting named on the
    resume replaces the saved one."""
    cmd = lambda *a: in_process(monkeypatch, capsys, tmp_path, *a)  # noqa: E731
    given = ("--width", 10, "--height", 6, "--spp", 2, "--exposure", 2.5, "--view", "agx", "--layers",
             "--method", "photon_map", "-O", "k=12", "--batch-paths", 5_000, "--quiet")
    assert cmd("render", BOX, *given, "--photons", 30_000, "-o", "whole.exr").returncode == 0
    assert cmd("render", BOX, *given, "--photons", 20_000, "-o", "part.exr", "--checkpoint", "c.npz").returncode == 0
    res = cmd("render", BOX, "--resume", "c.npz", "--more", 10_000)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["wrote", "part.exr", "wrote", "part.png"]  # the saved -o
    _same_files(tmp_path / "whole.exr", tmp_path / "part.exr")
    # named on the resume: another output and exposure, the same run
    res = cmd("render", BOX, "--resume", "c.npz", "--exposure", 2.5, "-o", "again.png", "--no-exr")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "again.png").read_bytes() == (tmp_path / "whole.png").read_bytes()
    assert not (tmp_path / "again.exr").exists()
    # irradiance: the points file, the output and the units saved as well
    np.save(tmp_path / "p.npy", np.array([[0.0, 0.01, 0.0, 0.0, 1.0, 0.0], [0.2, 0.01, -0.1, 0.0, 1.0, 0.0]]))
    args = ("irradiance", BOX, "--points", "p.npy", "--units", "photometric", "--quiet")
    assert cmd(*args, "--photons", 30_000, "-o", "whole.csv").returncode == 0
    assert cmd(*args, "--photons", 20_000, "-o", "part.csv", "--checkpoint", "i.npz").returncode == 0
    res = cmd("irradiance", BOX, "--resume", "i.npz", "--more", 10_000)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "part.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    _refused(cmd("irradiance", BOX, "-o", "x.npy"), "--points is required")


def test_run_api_resume_and_extend_equal_one_run(scenes_dir):
    """The same through the API, for every estimator: a run stopped after a
    few batches, its state restored into a fresh engine's run, and a run
    extended; accumulators equal one run's, bit for bit."""
    engine = oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml"))
    pts = engine.camera_points(width=10, height=10)
    for method in METHODS:
        opts = {"k": 10} if method == "photon_map" else {}
        whole = engine.irradiance(pts, method=method, photons=40_000, **opts)
        run = engine.run(pts, method=method, photons=40_000, **opts)
        run.set_batch(7_000)
        run.step(), run.step()
        state = run.state()
        other = oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_box.toml")).run(pts, method=method,
                                                                                      photons=40_000, **opts)
        other.restore(state)
        got = other.complete(False)
        assert got.accumulators.tobytes() == whole.accumulators.tobytes(), method
        assert got.irradiance.tobytes() == whole.irradiance.tobytes(), method
        assert got.stats.segments == whole.stats.segments
        short = engine.run(pts, method=method, photons=25_000, **opts)
        short.complete(False)
        short.extend(15_000)
        assert short.complete(False).irradiance.tobytes() == whole.irradiance.tobytes(), method
    # ranges tile: the parts of a split cover the range once, in order
    parts = [PathRange(5, 17).split(4, i) for i in range(4)]
    assert [(p.first, p.count) for p in parts] == [(5, 5), (10, 4), (14, 4), (18, 4)]


def test_progressive_images_and_the_final_one(tmp_path, monkeypatch, capsys):
    args = _args("prog.exr", "detp_disc_index", 60_000)
    res = in_process(monkeypatch, capsys, tmp_path, *args, "--progressive", 20_000)
    assert res.returncode == 0 and res.stderr == "", res.stderr  # --quiet: no lines
    res = in_process(monkeypatch, capsys, tmp_path, *args[:-1], "--progressive", 20_000)
    assert res.returncode == 0, res.stderr
    assert [ln.split(":")[1].strip() for ln in res.stderr.splitlines() if "photons: wrote" in ln] == \
        ["20,000 photons", "40,000 photons"]
    assert in_process(monkeypatch, capsys, tmp_path, *_args("plain.exr", "detp_disc_index", 60_000)).returncode == 0
    _same_files(tmp_path / "prog.exr", tmp_path / "plain.exr")


def _refused(res, match):
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("oclgi: error: ") and match in lines[0], lines


def test_another_runs_checkpoint_is_refused(tmp_path, scenes_dir, monkeypatch, capsys):
    cmd = lambda *a: in_process(monkeypatch, capsys, tmp_path, *a)  # noqa: E731
    n = 20_000
    assert cmd(*_args("a.exr", "detp_disc_index", n), "--checkpoint", "c.npz").returncode == 0
    before = (tmp_path / "c.npz").read_bytes()
    cases = [
        (_args("b.exr", "detp_disc_index", n, "--seed", 7), "its seed is 1, this run's 7"),
        (_args("b.exr", "detp_disc_index", n, "--radius", 0.05), "its radius is"),
        (_args("b.exr", "detp", n), "its method is 'detp_disc_index', this run's 'detp'"),
        (_args("b.exr", "detp_disc_index", 30_000), "its photons is 20000, this run's 30000"),
        (_args("b.exr", "detp_disc_index", n, "--width", 8), "its query points differ"),
        (("render", scenes_dir / "cornell_bunny.toml", "--photons", n, "--width", SIZE, "--height", SIZE,
          "-o", "b.exr", "--quiet"), "its scene differs"),
    ]
    for args, match in cases:
        _refused(cmd(*args, "--resume", "c.npz"), match)
        assert not (tmp_path / "b.exr").exists() and not (tmp_path / "b.png").exists()
    assert (tmp_path / "c.npz").read_bytes() == before  # a refused resume leaves the checkpoint alone
    # not a checkpoint, a missing one, misuse of the flags
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    base = _args("b.exr", "detp_disc_index", n)
    _refused(cmd(*base, "--resume", "junk.npz"), "not an oclgi checkpoint")
    _refused(cmd(*base, "--resume", "none.npz"), "no such checkpoint file")
    _refused(cmd(*base, "--more", 10), "give --resume FILE too")
    _refused(cmd(*base, "--checkpoint", "c.npz"), "c.npz exists")
    _refused(cmd(*base, "--checkpoint", "c.txt"), "must end in .npz")
    assert not (tmp_path / "b.exr").exists()


def test_crafted_checkpoints_are_one_line(tmp_path, monkeypatch, capsys):
    """A record nested 100,000 deep, a member whose header declares 10^20
    elements, a record that is not an object: each is refused in one line
    with status 2 before any work, never a traceback."""
    def npz(path, members):
        with zipfile.ZipFile(path, "w") as z:
            for name, data in members.items():
                z.writestr(name + ".npy", data)

    def npy(header: str, body: bytes = b"") -> bytes:
        h = header.encode().ljust(118) + b"\n"
        return b"\x93NUMPY\x01\x00" + len(h).to_bytes(2, "little") + h + body

    def saved(text: bytes) -> bytes:  # np.save's .npy of the bytes
        buf = io.BytesIO()
        np.save(buf, np.frombuffer(text, np.uint8))
        return buf.getvalue()

    npz(tmp_path / "deep.npz", {"meta": saved(("[" * 100_000 + "]" * 100_000).encode())})
    huge = npy("{'descr': '<i8', 'fortran_order': False, 'shape': (100000000000000000000,), }")
    meta = json.dumps({"format": 1, "first": 0, "count": 1, "next_path": 0, "segments": 0}).encode()
    npz(tmp_path / "huge.npz", {"meta": saved(meta), "sums.acc": huge})
    npz(tmp_path / "list.npz", {"meta": saved(b"[1, 2]")})
    for name in ("deep.npz", "huge.npz", "list.npz"):
        res = in_process(monkeypatch, capsys, tmp_path, *_args("x.exr", "detp_disc_index", 1000), "--resume", name)
        _refused(res, "checkpoint")
        assert "Traceback" not in res.stderr and not (tmp_path / "x.exr").exists()


def test_two_runs_cannot_share_a_checkpoint(tmp_path, monkeypatch, capsys):
    """Two runs started together with the same --checkpoint: the second is
    refused at once (the first's saves would be replaced by its own), and a
    run killed by SIGKILL leaves no lock that stops the next one."""
    p = _start(tmp_path, *_args("a.exr", "detp_disc_index"), "--checkpoint", "c.npz", "--checkpoint-every", "0")
    try:
        _wait_for(tmp_path / ".c.npz.oclgi-lock", p)
        second = in_process(monkeypatch, capsys, tmp_path, *_args("b.exr", "detp_disc_index"), "--checkpoint", "c.npz")
        _refused(second, "c.npz is the checkpoint of another oclgi run going on now")
        _wait_for(tmp_path / "c.npz", p)
        resumed = in_process(monkeypatch, capsys, tmp_path, *_args("b.exr", "detp_disc_index"), "--resume", "c.npz")
        _refused(resumed, "another oclgi run going on now")  # a resume of it too, while it runs
    finally:
        p.send_signal(signal.SIGKILL)
        p.communicate(timeout=60)
    assert not (tmp_path / "b.exr").exists()
    res = in_process(monkeypatch, capsys, tmp_path, *_args("a.exr", "detp_disc_index"), "--resume", "c.npz")
    assert res.returncode == 0, res.stderr
    assert not (tmp_path / ".c.npz.oclgi-lock").exists()


@pytest.mark.parametrize("cases, seed", [(12, 0), pytest.param(200, 1, marks=pytest.mark.full)])  # full: a campaign
def test_damaged_checkpoints_resume_or_stop_in_one_line(tmp_path, monkeypatch, capsys, cases, seed):
    """A finished run's checkpoint with random bytes flipped or cut short:
    each resume goes on or stops with one line and status 2, never a
    traceback, and writes nothing when it stops."""
    cmd = lambda *a: in_process(monkeypatch, capsys, tmp_path, *a)  # noqa: E731
    assert cmd(*_args("a.exr", "detp_disc_index", 5_000), "--checkpoint", "c.npz").returncode == 0
    good = (tmp_path / "c.npz").read_bytes()
    rng = np.random.default_rng(seed)
    for case in range(cases):
        data = bytearray(good)
        if case % 4 == 3:
            data = data[:int(rng.integers(0, len(data)))]  # cut short
        else:
            for i in rng.integers(0, len(data), int(rng.integers(1, 9))):
                data[i] ^= 1 << int(rng.integers(8))
        (tmp_path / "f.npz").write_bytes(bytes(data))
        res = cmd(*_args(f"f{case}.exr", "detp_disc_index", 5_000), "--resume", "f.npz")
        assert "Traceback" not in res.stderr, (case, res.stderr)
        if res.returncode != 0:
            assert res.returncode == 2 and res.stderr.count("\n") == 1 and res.stderr.startswith("oclgi: error: "), \
                (case, res.stderr)
            assert not (tmp_path / f"f{case}.exr").exists()
