"""The same command with the same seed writes the same bytes: renders can be
compared with cmp and checksummed (no time stamp in the files' metadata)."""

import hashlib
import time

from cli_run import run

ARGS = ("--photons", "3000", "--width", "16", "--height", "12", "--quiet")


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_two_renders_with_the_same_seed_are_byte_identical(tmp_path, scenes_dir):
    scene = scenes_dir / "cornell_box.toml"
    first = run(tmp_path, "render", scene, *ARGS, "--seed", "7", "-o", tmp_path / "a" / "img.exr")
    assert first.returncode == 0, first.stderr
    time.sleep(1.1)  # a time stamp with one-second resolution would now differ
    second = run(tmp_path, "render", scene, *ARGS, "--seed", "7", "-o", tmp_path / "b" / "img.exr")
    assert second.returncode == 0, second.stderr
    for name in ("img.exr", "img.png"):
        assert _digest(tmp_path / "a" / name) == _digest(tmp_path / "b" / name), name
    other = run(tmp_path, "render", scene, *ARGS, "--seed", "8", "-o", tmp_path / "c" / "img.exr")
    assert other.returncode == 0, other.stderr
    assert _digest(tmp_path / "c" / "img.exr") != _digest(tmp_path / "a" / "img.exr")
