"""Output files are whole or absent (issue #14): a full disk is an error, not
an empty file; SIGTERM leaves no temporary file and SIGKILL's leftovers are
swept by the next run; no output replaces an input or a file the user did not
name; an unwritable place fails before any work; a failed animation adds no
frame.

The full disk is a process whose file size is limited (RLIMIT_FSIZE with
SIGXFSZ ignored): every write past the limit fails with EFBIG, as on a full
disk with ENOSPC, and the limit costs no root and no mount.
"""

import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from cli_run import in_process
from small_scene import MOVING_BLOCK as MOVING, write_scene

from oclgi import io, tempfiles
from oclgi.errors import OclgiError
from oclgi.incremental.animate import animate, poses

@pytest.fixture
def scene(tmp_path):
    return write_scene(tmp_path)


@pytest.fixture
def oclgi(monkeypatch, capsys):
    """``oclgi ARGS`` in-process in ``cwd``: (exit status, stdout, stderr)."""
    def run_(cwd, *args):
        done = in_process(monkeypatch, capsys, cwd, *args)
        return done.returncode, done.stdout, done.stderr

    return run_


def _no_work(*args, **kwargs):
    raise AssertionError("the run started its work before refusing")


@pytest.fixture
def no_work(monkeypatch):
    """Refusals must come before any work: loading the scene fails the test."""
    import oclgi.cli

    monkeypatch.setattr(oclgi.cli, "_engine", _no_work)


def snapshot(d: Path) -> dict:
    """Every file under ``d`` (hidden ones too) with its bytes."""
    return {p.relative_to(d): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture
def refuses(cli_fails):
    """``oclgi ARGS`` in ``cwd`` refused: exit status 2, one error line holding
    ``match``, nothing on stdout, every file under ``cwd`` as it was."""
    def check(cwd, *args, match):
        before = snapshot(cwd)
        cli_fails(cwd, *args, match=re.escape(match), alone=True)
        assert snapshot(cwd) == before

    return check


def software(path) -> str:
    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.spec().get_string_attribute("Software")
    finally:
        inp.close()


# -- a full disk -----------------------------------------------------------------------------

def _limited(limit: int):
    """A subprocess set-up: writes past ``limit`` bytes fail with EFBIG."""
    def setup():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return setup


WRITERS = textwrap.dedent("""
    import sys
    import numpy as np
    from oclgi import io
    from oclgi.errors import OclgiError

    out = sys.argv[1]
    img = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)
    cases = {
        "images": lambda: io.write_images({out + "/x.exr": img, out + "/x.png": (img * 255).astype(np.uint8)}),
        "png": lambda: io.write_image(out + "/y.png", (img * 255).astype(np.uint8)),
        "exr": lambda: io.write_image(out + "/y.exr", img),
        "npy": lambda: io.write_array(out + "/e.npy", np.ones((500, 3))),
        "csv": lambda: io.write_array(out + "/e.csv", np.ones((500, 3))),
        "text": lambda: io.write_array_text(out + "/t.csv", ["a", "b"], [[i, 0.5] for i in range(500)]),
    }
    for name, write in cases.items():
        try:
            write()
            print(name, "wrote")
        except OclgiError as exc:
            print(name, "error", exc)
""")


@pytest.mark.parametrize("limit", [0, 100, 3000])
def test_full_disk_is_an_error_and_leaves_no_file(tmp_path, limit):
    # 0: nothing fits; 100: a header part-way; 3000: the PNG's header and
    # part of its pixels (the case PNG's writer reported as a success).
    res = subprocess.run([sys.executable, "-c", WRITERS, str(tmp_path)], capture_output=True, text=True,
                         preexec_fn=_limited(limit), timeout=120)
    assert res.returncode == 0, res.stderr
    lines = dict(line.split(" ", 1) for line in res.stdout.splitlines())
    assert set(lines) == {"images", "png", "exr", "npy", "csv", "text"}, res.stdout
    for name, said in lines.items():
        assert said.startswith("error cannot write "), (name, said)
        assert ".oclgi-tmp-" not in said, said  # the error names the output, not the temporary file
    assert res.stderr == ""  # libpng's own complaint about the short file is not shown
    assert list(tmp_path.iterdir()) == []


def test_full_disk_cli_render(scene, tmp_path):
    """The render itself runs unlimited; the limit starts with the writing."""
    script = textwrap.dedent("""
        import resource, signal, sys
        from oclgi import io, cli

        real = io.write_images

        def full_disk(images, **kw):
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (200, 200))
            return real(images, **kw)

        io.write_images = full_disk
        sys.exit(cli.main(sys.argv[1:]))
    """)
    before = snapshot(tmp_path)
    res = subprocess.run([sys.executable, "-c", script, "render", "s.toml", "-o", "x.exr", "--quiet"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2, res.stderr
    assert res.stdout == ""  # no "wrote ..."
    assert res.stderr.startswith("oclgi: error: cannot write x.") and res.stderr.count("\n") == 1, res.stderr
    assert snapshot(tmp_path) == before


def test_several_files_are_all_or_nothing(tmp_path):
    # Each file is checked before any is renamed: the study's report, made of
    # several files, is written this way.
    with pytest.raises(OclgiError, match="cannot write .*b.md: nothing reached the disk"):
        with io.atomic_paths([tmp_path / "a.md", tmp_path / "b.md"]) as (a, b):
            a.write_text("complete")  # b stays empty, as on a full disk
    assert list(tmp_path.iterdir()) == []


def test_written_files_are_checked_whole(tmp_path):
    io.write_images({tmp_path / "x.exr": np.ones((4, 5, 3), np.float32),
                     tmp_path / "x.png": np.full((4, 5, 3), 200, np.uint8)})
    assert io.read_image(tmp_path / "x.exr").shape == (4, 5, 3)
    assert software(tmp_path / "x.exr") == software(tmp_path / "x.png") == "oclgi"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.exr", "x.png"]


# -- SIGTERM and SIGKILL -----------------------------------------------------------------------

SLOW_WRITE = textwrap.dedent("""
    import sys, time
    from oclgi import io, cli

    real = io.write_image_file

    def slow(tmp, path, pixels, *args):
        real(tmp, path, pixels, *args)
        print("writing", flush=True)  # the temporary file exists now
        # Short sleeps: the signal may reach one of the OpenCL runtime's
        # threads, and Python runs its handler only once the main thread wakes.
        for _ in range(600):
            time.sleep(0.1)

    io.write_image_file = slow
    sys.exit(cli.main(sys.argv[1:]))
""")


def _signalled(script, args, cwd, ready, sig, temporary_first=True):
    """``python -c script args`` in ``cwd``, sent ``sig`` once it printed the
    line ``ready`` (a temporary file under ``cwd`` by then, unless not
    ``temporary_first``); returns the ended process."""
    proc = subprocess.Popen([sys.executable, "-c", script, *args], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == ready, proc.stderr.read()
        assert not temporary_first or any(tempfiles.is_temporary(p.name) for p in cwd.iterdir())
        proc.send_signal(sig)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    return proc


RENDER_X = ["render", "s.toml", "-o", "x.exr", "--quiet"]


def test_sigterm_while_writing_leaves_no_temporary_file(scene, tmp_path):
    before = snapshot(tmp_path)
    proc = _signalled(SLOW_WRITE, RENDER_X, tmp_path, "writing\n", signal.SIGTERM)
    # Ended by the signal (or, where a handler turns it into an exit, with 128 + 15).
    assert proc.returncode in (-signal.SIGTERM, 128 + signal.SIGTERM), proc.returncode
    assert "Traceback" not in proc.stderr.read() and snapshot(tmp_path) == before


def test_sigkill_leftover_is_removed_by_the_next_run(oclgi, scene, tmp_path):
    before = snapshot(tmp_path)
    # SIGKILL: no handler runs
    proc = _signalled(SLOW_WRITE, RENDER_X, tmp_path, "writing\n", signal.SIGKILL, temporary_first=False)
    left = [p.name for p in tmp_path.iterdir() if tempfiles.is_temporary(p.name)]
    assert left and all(f"-{proc.pid}-" in name for name in left)
    rc, out, err = oclgi(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "e.npy", "--quiet")
    assert rc == 0, err
    assert snapshot(tmp_path).keys() == {*before, Path("e.npy")}


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_stale_temporary_files_are_removed_by_the_next_write(tmp_path):
    dead, live = _dead_pid(), os.getppid()
    stale = [f".x.oclgi-tmp-{dead}-0123abcd.exr", f".frames.oclgi-tmp-{dead}-89abcdef"]
    kept = [f".x.oclgi-tmp-{live}-0123abcd.png",  # its process still runs
            f".x.oclgi-tmp-{dead}-mine.png",  # not oclgi's pattern
            "notes.txt", ".x.e1b2c3d4.exr"]  # a user's; the old temporary names
    (tmp_path / stale[0]).write_bytes(b"partial")
    (tmp_path / stale[1]).mkdir()
    (tmp_path / stale[1] / "frame_0000.png").write_bytes(b"frame")
    for name in kept:
        (tmp_path / name).write_bytes(b"keep")
    io.write_image(tmp_path / "y.exr", np.zeros((2, 2, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept + ["y.exr"])
    assert all((tmp_path / name).read_bytes() == b"keep" for name in kept)


def test_temporary_names_carry_the_pid(tmp_path):
    with io.atomic_path(tmp_path / "x.exr") as tmp:
        assert tmp.name.startswith(f".x.oclgi-tmp-{os.getpid()}-") and tmp.suffix == ".exr"
        assert tempfiles.is_temporary(tmp.name)
        io.write_image_file(tmp, tmp_path / "x.exr", np.zeros((2, 2, 3), np.float32))


# -- no output replaces an input ------------------------------------------------------------------

def test_irradiance_output_is_not_the_points_file(no_work, refuses, scene, tmp_path):
    for out in ("p.csv", "./p.csv", tmp_path / "p.csv"):
        refuses(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", out,
                match="it is the points file (--points)")
    os.symlink("p.csv", tmp_path / "link.csv")
    refuses(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "link.csv", match="it is the points file")


@pytest.mark.parametrize("out", ["scene.exr", "scene.png"])  # the file -o names, or its sibling
def test_render_output_is_not_the_scene_file(no_work, refuses, tmp_path, out):
    write_scene(tmp_path, name="scene.exr")
    refuses(tmp_path, "render", "scene.exr", "-o", out, "--quiet", match="it is the scene file")


def test_animate_output_is_not_the_keyframes_file(no_work, refuses, tmp_path):
    (tmp_path / "m.toml").write_text(MOVING)
    (tmp_path / "anim").mkdir()
    (tmp_path / "anim" / "timing.csv").write_text("0,0,0\n0.5,0,0\n")
    refuses(tmp_path, "animate", "m.toml", "--path", "anim/timing.csv", "--frames", 2, "-o", "anim",
            match="it is the keyframes file (--path)")


# -- the sibling image -------------------------------------------------------------------------------

def test_sibling_never_replaces_a_users_file(oclgi, refuses, scene, tmp_path):
    (tmp_path / "photo.png").write_bytes(b"my photo")
    refuses(tmp_path, "render", "s.toml", "-o", "photo.exr", "--quiet",
            match="photo.png exists and oclgi did not write it")

    rc, out, err = oclgi(tmp_path, "render", "s.toml", "-o", "photo.exr", "--no-png", "--quiet")
    assert rc == 0, err
    assert out == "wrote photo.exr\n" and (tmp_path / "photo.png").read_bytes() == b"my photo"

    rc, out, err = oclgi(tmp_path, "render", "s.toml", "-o", "photo.exr", "--force", "--quiet")
    assert rc == 0, err
    assert software(tmp_path / "photo.png") == "oclgi"


def test_sibling_of_a_png_and_reruns(oclgi, refuses, scene, tmp_path):
    for named in ("x.exr", "x.png", "x.exr"):  # each run replaces oclgi's own files (make render does this)
        rc, out, err = oclgi(tmp_path, "render", "s.toml", "-o", named, "--quiet")
        assert rc == 0, err
        assert out == "wrote x.exr\nwrote x.png\n"
    (tmp_path / "y.exr").write_bytes(b"not an image")
    refuses(tmp_path, "render", "s.toml", "-o", "y.png", "--quiet", match="y.exr exists and oclgi did not")
    rc, out, err = oclgi(tmp_path, "render", "s.toml", "-o", "y.png", "--no-exr", "--quiet")
    assert rc == 0, err
    assert out == "wrote y.png\n" and (tmp_path / "y.exr").read_bytes() == b"not an image"


def test_default_outputs_are_both_protected(no_work, refuses, scene, tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "s.exr").write_bytes(b"mine")
    refuses(tmp_path, "render", "s.toml", "--quiet", match="s.exr exists and oclgi did not write it")


@pytest.mark.parametrize("args,match", [
    (["-o", "x.png", "--no-png"], "--no-png contradicts -o x.png"),
    (["-o", "x.exr", "--no-exr"], "--no-exr contradicts -o x.exr"),
    (["--no-png", "--no-exr"], "leave nothing to write"),
])
def test_sibling_flags_that_contradict(no_work, refuses, scene, tmp_path, args, match):
    refuses(tmp_path, "render", "s.toml", *args, "--quiet", match=match)


@pytest.mark.parametrize("command", [["render", "s.toml"], ["animate", "s.toml", "--path", "line:1,0,0", "-o", "a"]])
@pytest.mark.parametrize("exposure", ["-1", "nan", "0", "inf"])
def test_bad_exposure_is_refused(no_work, refuses, scene, tmp_path, command, exposure):
    wanted = "expected 'auto' or a positive number" if command[0] == "render" else "expected a positive number"
    refuses(tmp_path, *command, "--exposure", exposure, match=f"argument --exposure: {wanted}")


# -- writability is checked first ----------------------------------------------------------------------

def test_virtual_file_system_fails_before_any_work(no_work, refuses, scene, tmp_path):
    # /proc takes no new files, for root too (who passes every permission check).
    refuses(tmp_path, "render", "s.toml", "-o", "/proc/oclgi-test.exr", "--quiet",
            match="cannot write /proc/oclgi-test.exr")
    refuses(tmp_path, "irradiance", "s.toml", "--points", "p.csv", "-o", "/proc/oclgi/e.npy", "--quiet",
            match="cannot write /proc/oclgi/e.npy")


def _as_unprivileged(cwd: Path, args) -> tuple[int, str]:
    """``oclgi ARGS`` in a forked child, as 'nobody' when the tests run as root
    (who passes every permission check): (exit status, stdout and stderr).

    A fork rather than a new interpreter: the modules are already loaded, so
    the child needs no read access to the interpreter's own files.
    """
    import oclgi.cli
    import oclgi.queries  # noqa: F401  (loaded before the child drops its rights)

    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child
        rc = 99
        try:
            os.close(r)
            os.dup2(w, 1)
            os.dup2(w, 2)
            sys.stdout = os.fdopen(1, "w")
            sys.stderr = os.fdopen(2, "w")
            if os.geteuid() == 0:
                os.setgroups([])
                os.setgid(65534)
                os.setuid(65534)
            os.chdir(cwd)
            oclgi.cli._engine = _no_work
            rc = oclgi.cli.main([str(a) for a in args])
        except SystemExit as exc:
            rc = exc.code
        except BaseException:
            import traceback

            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(rc)
    os.close(w)
    with os.fdopen(r) as f:
        text = f.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), text


def test_read_only_places_fail_before_any_work():
    """A read-only folder and a read-only file. The refusal comes before the
    scene is loaded, so no OpenCL is touched."""
    with tempfile.TemporaryDirectory(prefix="oclgi-ro-") as d:
        d = Path(d)
        os.chmod(d, 0o755)  # 'nobody' reads the scene
        write_scene(d)
        (d / "ro").mkdir()
        os.chmod(d / "ro", 0o555)
        (d / "e.npy").write_bytes(b"old")
        os.chmod(d / "e.npy", 0o444)
        before = snapshot(d)
        for args, match in ((["render", "s.toml", "-o", "ro/x.exr"], "cannot write ro/x.exr: permission denied"),
                            (["render", "s.toml", "-o", "ro/new/x.exr"], "cannot write ro/new/x.exr"),
                            (["irradiance", "s.toml", "--points", "p.csv", "-o", "e.npy"],
                             "cannot write e.npy: the file is read-only")):
            rc, text = _as_unprivileged(d, args)
            assert rc == 2, text
            assert text.startswith(f"oclgi: error: {match}") and text.count("\n") == 1, text
        assert snapshot(d) == before


# -- animations ---------------------------------------------------------------------------------------------

class FakeSession:
    """The two calls animate() makes; ``fail_at`` raises at that frame,
    ``hang_at`` says so on stdout and waits there."""

    def __init__(self, fail_at=None, hang_at=None, look=None):
        self.fail_at, self.hang_at, self.frame = fail_at, hang_at, -1
        self.look, self.seen = look, []  # the entries of folder ``look`` at each frame

    def move(self, name, pose):
        from oclgi.incremental.session import UpdateStats

        self.frame += 1
        if self.look is not None:
            self.seen.append(sorted(os.listdir(self.look)))
        if self.frame == self.fail_at:
            raise OclgiError("the device ran out of memory")
        if self.frame == self.hang_at:
            print("frames written", flush=True)
            import time

            for _ in range(600):  # short sleeps, as in SLOW_WRITE
                time.sleep(0.1)
        return UpdateStats(paths=1, segments_removed=0, segments_added=0, points=4, seconds={"total": 0.001})

    def render(self, exposure):
        return np.ones((2, 2, 3), np.float32), np.full((2, 2, 3), 128, np.uint8)


def test_failed_animation_adds_no_frame(tmp_path):
    with pytest.raises(OclgiError, match="out of memory"):
        animate(FakeSession(fail_at=2), "block", "line:1,0,0", 4, tmp_path / "new", write_exr=True)
    assert list(tmp_path.iterdir()) == []  # no folder, no frame, no temporary folder

    old = tmp_path / "old"
    old.mkdir()
    (old / "frame_0000.png").write_bytes(b"earlier run")
    with pytest.raises(OclgiError):
        animate(FakeSession(fail_at=3), "block", "line:1,0,0", 4, old)
    assert snapshot(tmp_path) == {Path("old/frame_0000.png"): b"earlier run"}

    session = FakeSession(look=tmp_path)
    rows = animate(session, "block", "line:1,0,0", 2, old)
    # An existing folder is staged inside it: its parent needs no write right.
    assert session.seen == [["old"], ["old"]] and len(rows) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]
    assert sorted(p.name for p in old.iterdir()) == ["frame_0000.png", "frame_0001.png", "timing.csv"]
    assert software(old / "frame_0000.png") == "oclgi"


def test_sigterm_during_animation_leaves_nothing(tmp_path):
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_outputs import FakeSession
        from oclgi.incremental.animate import animate

        from pathlib import Path
        animate(FakeSession(hang_at=2), "block", "line:1,0,0", 4, Path(sys.argv[1]))
    """)
    proc = _signalled(script, [str(tmp_path / "anim")], tmp_path, "frames written\n", signal.SIGTERM)
    assert proc.returncode in (-signal.SIGTERM, 128 + signal.SIGTERM), proc.returncode
    assert list(tmp_path.iterdir()) == []


IDENTITY = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]


@pytest.mark.parametrize("bad,match", [
    ([2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1], "singular"),  # a zero scale
    ([0] * 15 + [1], "singular"),
    ([1, 2, 0, 0, 2, 4, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "singular"),  # two equal directions
    (IDENTITY[:12] + [0, 0, 0.5, 1], "projective"),
    (IDENTITY[:15] + [2], "projective"),
])
def test_keyframe_matrices_are_checked(tmp_path, bad, match):
    keys = tmp_path / "k.csv"
    keys.write_text(",".join(map(str, IDENTITY)) + "\n" + ",".join(map(str, bad)) + "\n")
    with pytest.raises(OclgiError, match=f"row 2 .*{match}"):
        poses(str(keys), 2)


def test_good_keyframe_matrices(tmp_path):
    small = [0.01, 0, 0, 1, 0, 0.01, 0, 2, 0, 0, -0.01, 3, 0, 0, 0, 1]  # a small scale and a mirror are poses
    np.save(tmp_path / "k.npy", np.array([IDENTITY, small], float))
    np.testing.assert_allclose(poses(str(tmp_path / "k.npy"), 2)[1][:3, 3], [1, 2, 3])


def test_bad_matrix_fails_before_any_work(no_work, refuses, tmp_path):
    (tmp_path / "m.toml").write_text(MOVING)
    (tmp_path / "k.csv").write_text(",".join(map(str, IDENTITY[:15] + [0])) + "\n")
    refuses(tmp_path, "animate", "m.toml", "--path", "k.csv", "--frames", 1, "-o", "anim",
            match="k.csv: the matrix of row 1 has the last row")
