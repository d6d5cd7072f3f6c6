"""The image pipeline: samples per pixel (each a query point, the photons
shared), their box filter, and alpha as coverage."""

import math

import numpy as np
import OpenImageIO as oiio
import pytest

import oclgi
from oclgi.engine import KEY, auto_exposure, sample_offsets


@pytest.fixture(scope="module")
def engine(scenes_dir):
    return oclgi.Engine(oclgi.load_file(scenes_dir / "cornell_bunny.toml"))


def test_samples_per_pixel_are_the_mean_of_one_sample_images(engine):
    kw = dict(photons=30_000, width=24, height=24)
    four = engine.render(spp=4, **kw)
    assert four.radiance.shape == (24, 24, 3) and four.stats.points == 4 * 24 * 24
    cam = engine.view_camera(None, 24, 24)
    offsets = sample_offsets(4)
    assert offsets[0] == (0.5, 0.5) and len(set(offsets)) == 4
    assert all(0 <= x < 1 and 0 <= y < 1 for x, y in offsets)
    singles = []
    for off in offsets:
        pts = engine.view_points(cam, (0, 0, 24, 24), offset=off)
        singles.append(engine.shade(pts, engine.irradiance(pts, photons=30_000).estimator.irr)[0])
    mean = np.mean(np.stack(singles).astype(np.float64), axis=0).astype(np.float32)
    assert four.radiance.tobytes() == mean.tobytes()  # the same sums per point, the same filter
    # one sample is the pixel's centre: the plain render, bit for bit
    one = engine.render(**kw)
    assert one.radiance.tobytes() == singles[0].tobytes()
    # the edges: pixels some samples of which miss the scene (the open front) have partial alpha
    alpha = four.pixels[..., 3]
    assert set(np.unique(one.pixels[..., 3])) <= {0, 255}
    partial = (alpha > 0) & (alpha < 255)
    assert partial.any() and (alpha == 0).any() and (alpha == 255).any()
    assert np.array_equal(alpha == 0, (one.pixels[..., 3] == 0) & (alpha == 0))


def test_spp_is_checked(engine):
    for bad in (0, 257, 1.5, True):
        with pytest.raises(oclgi.OclgiError, match="spp"):
            engine.render(photons=1000, width=8, height=8, spp=bad)


def test_images_say_how_they_were_made(engine, tmp_path):
    result = engine.render(photons=20_000, width=16, height=16, spp=2, seed=7, method="impact")
    exr, png = oclgi.save_render(result, tmp_path / "r.exr")
    for path in (exr, png):
        spec = oiio.ImageInput.open(str(path)).spec()
        got = {a.name: spec.getattribute(a.name) for a in spec.extra_attribs if a.name.startswith("oclgi:")}
        assert got == result.metadata, path
    m = result.metadata
    assert (m["oclgi:method"], m["oclgi:photons"], m["oclgi:seed"], m["oclgi:spp"]) == ("impact", "20000", "7", "2")
    assert m["oclgi:camera_position"] == "0 1 3.94" and m["oclgi:version"] == oclgi.__version__
    assert m["oclgi:segments"] == str(result.stats.segments)


def test_layers_irradiance_albedo_normal_depth(engine, tmp_path):
    result = engine.render(photons=20_000, width=16, height=16, layers=True)
    lay = result.layers
    assert list(lay) == ["irradiance", "albedo", "normal", "depth"]
    hit = result.pixels[..., 3] == 255
    # the radiance is the layers' product where no emitter is seen (L = albedo E / pi)
    tri = result.estimate.points.tri.reshape(16, 16)
    emission = np.array([m.emission for m in engine.scene.materials])[engine.scene.tri_material[tri]].sum(axis=2)
    lit = hit & (emission == 0)
    assert lit.sum() > 100 and (hit & ~lit).any()  # the light is seen too
    np.testing.assert_allclose(result.radiance[lit], (lay["albedo"] * lay["irradiance"] / math.pi)[lit],
                               rtol=2e-6, atol=1e-9)
    assert np.array_equal(lay["irradiance"].reshape(-1, 3)[hit.ravel()], result.estimate.irradiance[hit.ravel()])
    assert np.allclose(np.linalg.norm(lay["normal"][hit], axis=1), 1, atol=1e-5)
    assert (lay["depth"][hit] > 1).all() and (lay["depth"][~hit] == 0).all()
    exr, _ = oclgi.save_render(result, tmp_path / "l.exr")
    buf = oiio.ImageBuf(str(exr))
    names = buf.spec().channelnames
    back = buf.get_pixels(oiio.FLOAT)
    for name, a in [("R", result.radiance[..., :1])] + [(f"{k}.{c}", v[..., i:i + 1]) for k, v in lay.items()
                                                        for i, c in enumerate(oclgi.engine.LAYER_CHANNELS[k])]:
        assert np.array_equal(back[..., names.index(name)], a[..., 0]), name
    plain = engine.render(photons=20_000, width=16, height=16)
    assert plain.layers == {} and plain.exr_channels()[1] == ["R", "G", "B"]


def test_auto_exposure_puts_the_log_average_at_middle_grey(engine):
    auto = engine.render(photons=20_000, width=16, height=16, exposure="auto")
    cover = (auto.pixels[..., 3] > 0).astype(np.float32)[..., None]
    x = auto_exposure(np.concatenate([auto.radiance, cover], axis=2).reshape(-1, 4))
    lum = auto.radiance.reshape(-1, 3).astype(np.float64) @ [0.2126, 0.7152, 0.0722]
    lit = (cover.ravel() > 0) & (lum > 0)
    assert np.exp(np.log(lum[lit] * x).mean()) == pytest.approx(KEY)
    fixed = engine.render(photons=20_000, width=16, height=16, exposure=x)
    assert fixed.pixels.tobytes() == auto.pixels.tobytes() and auto.metadata["oclgi:exposure"] == "auto"
    assert engine.render(photons=20_000, width=16, height=16).pixels.tobytes() != auto.pixels.tobytes()
