"""``oclgi warm`` fills PoCL's kernel cache with every kernel a render
launches, whatever its size: a render after it compiles nothing."""

import os

from cli_run import run


def _entries(cache):
    """Every file in PoCL's cache, by path (kernels are stored one folder each)."""
    out = set()
    for root, _dirs, files in os.walk(cache):
        out.update(os.path.relpath(os.path.join(root, f), cache) for f in files
                   if f != "last_accessed" and not f.startswith("tempfile"))
    return out


def test_a_render_after_warm_compiles_nothing(tmp_path, scenes_dir):
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "cache"))
    res = run(tmp_path, "warm", env=env, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "programs" in res.stderr and "kernels compiled" in res.stderr
    warmed = _entries(tmp_path / "cache")
    assert any(p.endswith(".so") for p in warmed), sorted(warmed)[:10]
    # The default scene at its own size: larger launches than the warm-up's; Photon Maps at another
    # work-group size; the bunny, whose scene tree is built on the device (oclgi/accel/bvh_sah_device.py).
    for scene, *args in (("cornell_box.toml", "--photons", "50000", "-o", tmp_path / "r.exr"),
                         ("cornell_box.toml", "--photons", "20000", "--method", "photon_map", "--local-size", "16",
                          "-o", tmp_path / "p.exr"),
                         ("cornell_bunny.toml", "--photons", "2000", "-o", tmp_path / "b.exr")):
        res = run(tmp_path, "render", scenes_dir / scene, *args, env=env, timeout=600)
        assert res.returncode == 0, res.stderr
        assert _entries(tmp_path / "cache") == warmed, scene
