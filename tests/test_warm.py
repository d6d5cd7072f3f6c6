"""``oclgi warm`` fills PoCL's kernel cache with every kernel a render
launches, whatever its size: a render after it compiles nothing."""

import os
import subprocess
import sys


def _entries(cache):
    """Every file in PoCL's cache, by path (kernels are stored one folder each)."""
    out = set()
    for root, _dirs, files in os.walk(cache):
        out.update(os.path.relpath(os.path.join(root, f), cache) for f in files
                   if f != "last_accessed" and not f.startswith("tempfile"))
    return out


def _oclgi(cwd, env, *args):
    return subprocess.run([sys.executable, "-m", "oclgi", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_a_render_after_warm_compiles_nothing(tmp_path, scenes_dir):
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "cache"))
    res = _oclgi(tmp_path, env, "warm")
    assert res.returncode == 0, res.stderr
    assert "programs" in res.stderr and "kernels compiled" in res.stderr
    warmed = _entries(tmp_path / "cache")
    assert any(p.endswith(".so") for p in warmed), sorted(warmed)[:10]
    # The default scene at its own size: larger launches than the warm-up's.
    res = _oclgi(tmp_path, env, "render", scenes_dir / "cornell_box.toml", "--photons", "50000",
                 "-o", tmp_path / "r.exr")
    assert res.returncode == 0, res.stderr
    assert _entries(tmp_path / "cache") == warmed
    res = _oclgi(tmp_path, env, "render", scenes_dir / "cornell_box.toml", "--photons", "20000",
                 "--method", "photon_map", "--local-size", "16", "-o", tmp_path / "p.exr")
    assert res.returncode == 0, res.stderr
    assert _entries(tmp_path / "cache") == warmed
    # The bunny's scene tree is built on the device (oclgi/accel/bvh_sah_device.py): warmed too.
    res = _oclgi(tmp_path, env, "render", scenes_dir / "cornell_bunny.toml", "--photons", "2000",
                 "-o", tmp_path / "b.exr")
    assert res.returncode == 0, res.stderr
    assert _entries(tmp_path / "cache") == warmed
