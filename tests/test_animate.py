"""`oclgi animate`: paths, frames, the timing log, and bad input."""

import numpy as np
import pytest
from cli_run import run
from small_scene import MOVING_BLOCK as SCENE

import oclgi
from oclgi.errors import OclgiError
from oclgi.incremental.animate import poses
from oclgi.io import read_image
from oclgi.video import write_video


def test_poses():
    line = poses("line:1,0,-2", 5)
    assert len(line) == 5
    np.testing.assert_allclose(line[0], np.eye(4))
    np.testing.assert_allclose(line[-1][:3, 3], [1, 0, -2])
    np.testing.assert_allclose(line[2][:3, 3], [0.5, 0, -1])
    orbit = poses("orbit:0.5", 9)
    np.testing.assert_allclose(orbit[0], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(orbit[4][:3, 3], [-1.0, 0, 0], atol=1e-12)  # half way round
    for spec in ("line:1,2", "orbit:-1", "spiral:2", "line:a,b,c", "line:1,nan,0"):
        with pytest.raises(OclgiError):
            poses(spec, 4)


def test_keyframe_file(tmp_path):
    keys = tmp_path / "k.csv"
    keys.write_text("0,0,0,0\n1,0,0,90\n")
    p = poses(str(keys), 3)
    np.testing.assert_allclose(p[1][:3, 3], [0.5, 0, 0])
    np.testing.assert_allclose(p[2][:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    bad = tmp_path / "bad.csv"
    bad.write_text("0,0\n")
    with pytest.raises(OclgiError, match=r"bad.csv:1: expected 3 or 4 or 16 columns"):
        poses(str(bad), 3)
    # the points files' rules: a header, comments, whitespace-separated fields
    same = tmp_path / "same.csv"
    same.write_text("# a path\nx y z angle\n0 0 0 0\n\n1 0 0 90\n")
    assert all(np.array_equal(a, b) for a, b in zip(poses(str(same), 3), p))
    bad.write_text("0,0,0\n1,0,0,90\n")
    with pytest.raises(OclgiError, match=r"bad.csv:2: expected 3 columns"):
        poses(str(bad), 3)


def test_animate_writes_frames_and_log(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "anim"
    r = run(None, "animate", scene, "--path", "line:0.5,0,0", "--frames", 3, "-o", out, "--exr",
             "--dynamic", "detp_sphere_cache")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["frame_0000.exr", "frame_0000.png", "frame_0001.exr",
                                                     "frame_0001.png", "frame_0002.exr", "frame_0002.png", "timing.csv"]
    log = (out / "timing.csv").read_text().splitlines()
    assert log[0].startswith("frame,paths,segments_removed") and len(log) == 4 and "updates/s" in r.stderr


@pytest.mark.parametrize("args,message", [
    (["--path", "zigzag:1", "--frames", "3"], "not line:"),
    (["--path", "line:1,0,0", "--object", "teapot"], "no movable object named 'teapot'"),
    (["--path", "line:1,0,0", "--dynamic", "impact"], "invalid choice: 'impact'"),
])
def test_animate_bad_input(tmp_path, args, message):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "anim"
    r = run(None, "animate", scene, *args, "-o", out)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    assert not out.exists() or not any(out.iterdir())


def test_poses_beyond_float32_coordinates_are_refused_before_any_work():
    """`orbit:1e300` (found by the fuzz campaign) made NaN instance boxes and
    a ValueError traceback in the dynamic view; a pose must stay within the
    coordinates the device holds."""
    with pytest.raises(OclgiError, match=r"frame 1's pose moves the object beyond 1e\+18"):
        poses("orbit:1e300", 2)
    with pytest.raises(OclgiError, match="beyond 1e\\+18"):
        poses("line:0,2e18,0", 3)
    assert len(poses("orbit:1e17", 2)) == 2


def test_a_move_beyond_float32_coordinates_is_refused(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    engine = oclgi.Engine(oclgi.load_file(scene), progress=False)
    far = np.eye(4)
    far[0, 3] = 1e300
    before = engine.compiled.instances_host.tobytes()
    with pytest.raises(OclgiError, match="places object 'block' beyond 1e\\+18"):
        engine.move("block", far)
    assert engine.compiled.instances_host.tobytes() == before  # a refused move changes nothing


def _animate_video(tmp_path, video: str, frames: int, fps: int, frame: int):
    """``animate --video`` of SCENE's block into tmp_path; (the video's path,
    frame number ``frame``'s PNG as 8-bit RGBA)."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "anim"
    r = run(None, "animate", scene, "--path", "line:0.5,0,0", "--frames", frames, "-o", out, "--video",
            tmp_path / video, "--fps", fps, "--quiet")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == f"wrote {tmp_path / video}"
    return tmp_path / video, np.rint(read_image(out / f"frame_{frame:04d}.png") * 255).astype(np.uint8)


def test_animate_writes_an_mp4_of_its_frames(tmp_path):
    """Through imageio's ffmpeg (the test extra installs imageio-ffmpeg's own
    binary): read back, the MP4 has every frame, the frames' size and rate,
    and the frames' pixels within H.264's loss."""
    import imageio_ffmpeg

    video, png = _animate_video(tmp_path, "a.mp4", 5, 12, 4)
    h, w = png.shape[:2]
    assert imageio_ffmpeg.count_frames_and_secs(str(video))[0] == 5
    reader = imageio_ffmpeg.read_frames(str(video))
    meta = next(reader)
    assert tuple(meta["size"]) == (w + w % 2, h + h % 2) and meta["fps"] == 12
    last = [np.frombuffer(f, np.uint8) for f in reader][-1].reshape(h + h % 2, w + w % 2, 3)[:h, :w]
    over_black = (png[..., :3].astype(np.uint16) * png[..., 3:] // 255).astype(np.int16)
    assert np.abs(last.astype(np.int16) - over_black).mean() < 6  # H.264 and its 4:2:0 colour


def test_mp4_of_odd_size_is_padded_to_even(tmp_path):
    """yuv420p needs even sides: the last column and row are repeated, not an ffmpeg failure."""
    import imageio_ffmpeg

    frames = [np.full((17, 33, 4), (30 * k, 100, 200, 255), np.uint8) for k in range(3)]
    path = write_video(tmp_path / "odd.mp4", frames, 10)
    assert imageio_ffmpeg.count_frames_and_secs(str(path))[0] == 3
    assert tuple(next(imageio_ffmpeg.read_frames(str(path)))["size"]) == (34, 18)


def test_animate_writes_a_gif_of_its_frames(tmp_path):
    from PIL import Image

    video, png = _animate_video(tmp_path, "a.gif", 3, 10, 0)
    with Image.open(video) as gif:
        first = np.asarray(gif.convert("RGBA"))
        total = 0  # Pillow folds a frame equal to the one before into its duration
        for k in range(gif.n_frames):
            gif.seek(k)
            total += gif.info["duration"]
        assert total == 300
    over_black = (png[..., :3].astype(np.uint16) * png[..., 3:] // 255).astype(np.int16)
    assert np.abs(first[..., :3].astype(np.int16) - over_black).max() <= 24  # GIF's 256-colour palette
    for bad, match in (("a.avi", "must end in .gif or .mp4"),):
        r = run(None, "animate", tmp_path / "s.toml", "--path", "line:0.5,0,0", "--frames", 3, "-o", tmp_path / "b",
                "--video", tmp_path / bad)
        assert r.returncode == 2 and match in r.stderr and not (tmp_path / "b").exists()
