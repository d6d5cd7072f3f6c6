"""View transforms (kernels/view_transform.h): the OpenCL kernel against
float64 references of the published formulas; srgb is what oclgi always
wrote; the EXR stays linear; the view is recorded and chosen from the
command line."""

import numpy as np
import OpenImageIO as oiio
import pyopencl as cl
import pytest

import oclgi
from oclgi import params
from oclgi.cl.programs import launch
from oclgi.engine import VIEW_IDS

from cli_run import in_process
from conftest import SCENES

# Troy Sobotka's AgX as most renderers use it (Wrensch's minimal fit): inset, log2 window, sigmoid, outset
AGX_INSET = np.array([[0.842479062253094, 0.0784335999999992, 0.0792237451477643],
                      [0.0423282422610123, 0.878468636469772, 0.0791661274605434],
                      [0.0423756549057051, 0.0784336, 0.879142973793104]])
AGX_MIN_EV, AGX_MAX_EV = -12.47393, 4.026069


def srgb(c):
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def agx(c):
    v = c @ AGX_INSET.T
    v = np.clip(np.log2(np.maximum(v, 1e-10)), AGX_MIN_EV, AGX_MAX_EV)
    x = (v - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV)
    s = np.polynomial.polynomial.polyval(x, [-0.00232, 0.1191, 0.4298, -6.868, 31.96, -40.14, 15.5])
    return np.clip(s @ np.linalg.inv(AGX_INSET).T, 0.0, 1.0)  # the outset: the inset's inverse


def filmic(c):
    x = np.maximum(c, 0.0)
    return srgb(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14))


REFERENCE = {"srgb": lambda c: srgb(c), "agx": agx, "filmic": filmic}


def radiance_samples():
    """Greys over 20 stops, saturated and mixed colours from dark to far over 1, and black."""
    grey = 2.0 ** np.arange(-14, 7, 0.5)
    colours = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0.5, 0.1], [0.2, 0.3, 0.9], [1, 1, 0]], np.float64)
    scale = 2.0 ** np.arange(-6, 8, 1.0)
    rgb = np.concatenate([np.repeat(grey[:, None], 3, 1), (colours[None] * scale[:, None, None]).reshape(-1, 3),
                          np.zeros((1, 3))])
    return rgb


@pytest.fixture(scope="module")
def engine():
    return oclgi.Engine(oclgi.load_file(SCENES / "cornell_box.toml"))


def tonemap(engine, rgb, view, exposure=1.0):
    rad = np.ones((len(rgb), 4), np.float32)
    rad[:, :3] = rgb
    mf = cl.mem_flags
    buf = cl.Buffer(engine.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=rad)
    out = cl.Buffer(engine.ctx, mf.WRITE_ONLY, len(rgb) * 4)
    launch(engine.queue, engine._programs.get("image").image_tonemap, len(rgb), buf, len(rgb), np.float32(exposure),
           np.int32(VIEW_IDS[view]), out)
    pixels = np.empty((len(rgb), 4), np.uint8)
    cl.enqueue_copy(engine.queue, pixels, out)
    return pixels


def test_every_view_has_a_kernel_id():
    assert sorted(VIEW_IDS) == sorted(params.VIEWS) and len(set(VIEW_IDS.values())) == len(VIEW_IDS)


@pytest.mark.parametrize("view", params.VIEWS)
def test_kernel_matches_the_float64_reference(engine, view):
    rgb = radiance_samples()
    got = tonemap(engine, rgb.astype(np.float32), view)
    want = np.rint(255 * REFERENCE[view](rgb.astype(np.float32).astype(np.float64)))
    assert np.abs(got[:, :3].astype(int) - want).max() <= 1  # float32 against float64: at most one level
    assert (got[:, 3] == 255).all()


def test_srgb_is_the_clamp_oclgi_always_wrote(engine):
    """The default view's bytes are the old kernel's: clamp, sRGB, round to nearest (exactly, in float32)."""
    rgb = radiance_samples().astype(np.float32)
    got = tonemap(engine, rgb, "srgb", exposure=1.7)
    c = np.clip(rgb * np.float32(1.7), 0, 1)
    enc = np.where(c <= np.float32(0.0031308), np.float32(12.92) * c,
                   np.float32(1.055) * c ** np.float32(1 / 2.4) - np.float32(0.055)).astype(np.float32)
    assert np.abs(got[:, :3].astype(int) - np.rint(255 * enc)).max() <= 1
    assert (got[rgb.max(axis=1) >= 1, :3] == 255).any(axis=1).all()  # highlights clip


def test_agx_and_filmic_roll_off_highlights(engine):
    grey = 2.0 ** np.arange(-8, 7, 0.5)
    rgb = np.repeat(grey[:, None], 3, 1).astype(np.float32)
    for view in ("agx", "filmic"):
        g = tonemap(engine, rgb, view)[:, 0].astype(int)
        assert (np.diff(g) >= 0).all(), view  # monotonic in exposure
        assert g[grey == 1.0][0] < 240 and g[grey == 4.0][0] < 255, view  # 1 and 4 do not clip
    # AgX desaturates bright saturated colours towards white (no hue skew to pure primaries)
    red = tonemap(engine, np.array([[0.05, 0, 0], [40, 0, 0]], np.float32), "agx")[:, :3].astype(int)
    assert red[1, 1] > 100 and red[1, 2] > 100 and red[0, 1] < 30
    # Narkowicz's pre-exposed fit: 1 maps to about 0.8 (linear) before the sRGB encoding
    one = tonemap(engine, np.array([[1, 1, 1]], np.float32), "filmic")[0, 0]
    assert abs(int(one) - round(255 * float(srgb(0.8037)))) <= 1


def test_render_view_keeps_the_radiance_and_records_itself(engine):
    kw = dict(photons=20_000, width=16, height=16)
    base = engine.render(**kw)
    for view in ("agx", "filmic"):
        r = engine.render(view=view, **kw)
        assert r.radiance.tobytes() == base.radiance.tobytes()
        assert r.pixels[..., :3].tobytes() != base.pixels[..., :3].tobytes()
        assert r.metadata["oclgi:view"] == view
    assert base.metadata["oclgi:view"] == "srgb"
    assert engine.render(view="SRGB", **kw).pixels.tobytes() == base.pixels.tobytes()
    with pytest.raises(oclgi.OclgiError, match="view: expected one of srgb, agx, filmic, got 'aces'"):
        engine.render(view="aces", **kw)


def test_cli_view(monkeypatch, capsys, tmp_path):
    args = ("render", SCENES / "cornell_box.toml", "--photons", "20000", "--width", "16", "--height", "16", "--quiet")
    r = in_process(monkeypatch, capsys, tmp_path, *args, "--view", "agx", "-o", tmp_path / "a.png")
    assert r.returncode == 0, r.stderr
    assert oiio.ImageInput.open(str(tmp_path / "a.png")).spec().getattribute("oclgi:view") == "agx"
    r = in_process(monkeypatch, capsys, tmp_path, *args, "--view", "log", "-o", tmp_path / "b.png")
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "oclgi: error: argument --view: expected one of srgb, agx, filmic, got 'log' (see `oclgi render --help`)"]
    assert not (tmp_path / "b.png").exists()
