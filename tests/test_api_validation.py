"""One validation gate for the Python API: public structures are checked when
made and where they meet an engine, so that no kernel is handed an array it
would read out of bounds or as the wrong type, and every refusal is one
OclgiError line naming the argument.

Before these checks: an out-of-range triangle id crashed the process under
Impact Count; float64 or (n, 3) arrays in a QueryPoints were read as float32
(n, 4) bytes and gave wrong values silently; ``render(width=0)`` used the
camera's size, ``render(exposure=-1)`` or NaN drew black or NaN pixels; a
radius whose 1 / (scale pi d^2) is 0 in float32 gave zero irradiance.
"""

import dataclasses
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import oclgi
from oclgi import params
from oclgi.errors import OclgiError
from oclgi.queries import QueryPoints

FLOOR = [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]
LIGHT = [[-0.2, 1, -0.2], [0.2, 1, -0.2], [0.2, 1, 0.2], [-0.2, 1, 0.2]]
DESC = {"name": "floor", "mesh": [{"vertices": FLOOR, "faces": [[0, 2, 1], [0, 3, 2]], "albedo": [0.5, 0.5, 0.5]},
                                  {"vertices": LIGHT, "faces": [[0, 1, 2], [0, 2, 3]], "emission": [5, 5, 5]}],
        "camera": {"position": [0, 0.5, 3], "look_at": [0, 0.3, 0], "width": 4, "height": 3}}
XYZN = np.array([[0.1, 0.0, 0.2, 0, 1, 0], [-0.3, 0.0, 0.1, 0, 1, 0]], float)


@pytest.fixture(scope="module")
def engine():
    return oclgi.Engine(oclgi.load_dict(DESC), progress=False)


def packed(tri=(-1, -1)):
    """XYZN as float32 QueryPoints arrays, with triangle ids ``tri``."""
    pos = np.zeros((2, 4), np.float32)
    pos[:, :3] = XYZN[:, :3]
    pos[:, 3] = np.asarray(tri, np.int32).view(np.float32)
    nrm = np.zeros((2, 4), np.float32)
    nrm[:, :3] = XYZN[:, 3:]
    return pos, nrm, np.zeros((2, 2), np.float32)


# -- QueryPoints --------------------------------------------------------------------------

@pytest.mark.parametrize("which", [0, 1, 2])
@pytest.mark.parametrize("dtype", [bool, complex, str, object])
def test_query_points_refuse_non_real_arrays(which, dtype):
    arrays = list(packed())
    arrays[which] = arrays[which].astype(dtype)
    name = ("positions", "normals", "barycentrics")[which]
    with pytest.raises(OclgiError, match=rf"^query points: {name} must be an array of real numbers, got dtype"):
        QueryPoints(*arrays)


@pytest.mark.parametrize("which, shape", [(0, (2, 5)), (0, (2,)), (1, (3, 4)), (1, (2, 2)), (2, (2, 3)),
                                          (2, (1, 2))])
def test_query_points_refuse_wrong_shapes(which, shape):
    arrays = list(packed())
    arrays[which] = np.zeros(shape, np.float32)
    with pytest.raises(OclgiError, match=r"^query points: \w+ must be a .* array.*, got shape"):
        QueryPoints(*arrays)


def test_float64_and_narrow_arrays_are_converted_by_value(engine):
    """Were read as float32 (n, 4) bytes: wrong values (or beyond the array's end)."""
    good = engine.irradiance(QueryPoints(*packed()), method="detp", photons=2000, radius=0.3).irradiance
    assert good.max() > 0
    pos, nrm, bary = packed()
    as64 = QueryPoints(pos[:, :3].astype(np.float64), nrm[:, :3].astype(np.float64), bary.astype(np.float64))
    assert as64.positions.dtype == np.float32 and as64.positions.shape == (2, 4) and (as64.tri == -1).all()
    np.testing.assert_array_equal(engine.irradiance(as64, method="detp", photons=2000, radius=0.3).irradiance, good)
    wide64 = np.concatenate([XYZN[:, :3], [[-1], [-1]]], axis=1)  # w: the triangle id by value
    q = QueryPoints(wide64, nrm.astype(np.float64), bary)
    np.testing.assert_array_equal(q.positions, pos)
    np.testing.assert_array_equal(engine.irradiance(q, method="detp", photons=2000, radius=0.3).irradiance, good)


def test_query_points_refuse_bad_values():
    pos, nrm, bary = packed()
    for a, value, match in ((pos, np.nan, "position has a NaN"),
                            (pos, 1e20, r"position has a NaN, infinite or huge \(beyond 1e18\)"),
                            (nrm, np.inf, "normal has a NaN"), (bary, np.nan, "barycentric has a NaN")):
        arrays = [x.copy() for x in (pos, nrm, bary)]
        k = [id(x) for x in (pos, nrm, bary)].index(id(a))
        arrays[k][1, 0] = value
        with pytest.raises(OclgiError, match=rf"^query point 1: {match}"):
            QueryPoints(*arrays)
    with pytest.raises(OclgiError, match=r"^query point 0: its normal has length 2, not 1"):
        QueryPoints(pos, nrm * 2, bary)
    with pytest.raises(OclgiError, match=r"^query point 1: triangle id -7 is neither -1"):
        QueryPoints(*packed((0, -7)))
    with pytest.raises(OclgiError, match=r"4th column \(the triangle id\) must be an integer"):
        QueryPoints(np.array([[0, 0, 0, 0.5]]), nrm[:1], bary[:1])
    with pytest.raises(OclgiError, match=r"shape \(2, 2\) does not hold 2 points"):
        QueryPoints(pos, nrm, bary, "camera", (2, 2))


def test_zero_normal_counts_nothing_other_lengths_are_refused(engine):
    """A camera pixel that sees nothing has a zero normal: no estimator counts there."""
    pos, nrm, bary = packed()
    nrm[0] = 0
    est = engine.irradiance(QueryPoints(pos, nrm, bary), method="detp", photons=2000, radius=0.3)
    assert (est.irradiance[0] == 0).all() and est.irradiance[1].max() > 0
    for length in (0.5, 1.01, 1e-6):
        with pytest.raises(OclgiError, match=r"^query point 1: its normal has length .*, not 1 \(1 such points; "
                                             r"oclgi.query_points normalises them\)$"):
            QueryPoints(pos, np.array([[0, 1, 0, 0], [0, length, 0, 0]], np.float32), bary)


def test_out_of_range_triangle_is_refused_not_a_crash(tmp_path):
    """Impact Count read faces[3 * tri] past the buffer's end: the process died."""
    script = textwrap.dedent(f"""
        import numpy as np, oclgi
        from oclgi.queries import QueryPoints
        engine = oclgi.Engine(oclgi.load_dict({DESC!r}), progress=False)
        pos = np.zeros((2, 4), np.float32)
        pos[:, 3] = np.array([1, 1 << 28], np.int32).view(np.float32)
        nrm = np.zeros((2, 4), np.float32); nrm[:, 1] = 1
        try:
            engine.irradiance(QueryPoints(pos, nrm, np.zeros((2, 2), np.float32)), method="impact", photons=1000)
        except oclgi.OclgiError as exc:
            print(exc)
    """)
    res = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == ("query point 1: triangle id 268435456 is out of range for scene 'floor' "
                                  "(4 triangles; -1 for none) (1 such points)")


@pytest.mark.parametrize("method", ["detp", "impact", "photon_map"])
def test_triangle_ids_checked_where_points_meet_the_engine(engine, method):
    q = QueryPoints(*packed((1, 4)))
    with pytest.raises(OclgiError, match=r"^query point 1: triangle id 4 is out of range for scene 'floor'"):
        engine.irradiance(q, method=method, photons=1000)
    with pytest.raises(OclgiError, match=r"triangle id 4 is out of range"):
        engine.estimator(q, engine.run_params(method))


def test_reassigned_arrays_are_checked_at_the_gate(engine):
    q = QueryPoints(*packed())
    q.positions = q.positions.astype(np.float64)
    with pytest.raises(OclgiError, match=r"^query points: positions must be a C-contiguous \(n, 4\) float32 array"):
        engine.irradiance(q, photons=1000)


@pytest.mark.parametrize("bad", [np.zeros((2, 6), bool), np.zeros((2, 6), complex), [["a"] * 6] * 2,
                                 np.array([[object()] * 6] * 2)])
def test_point_arrays_refuse_non_numbers(engine, bad):
    with pytest.raises(OclgiError, match=r"^points must be an array of real numbers, got dtype"):
        engine.irradiance(bad, photons=1000)
    with pytest.raises(OclgiError, match=r"^points must be an array of real numbers"):
        oclgi.query_points(np.asarray(bad)[:, :3], XYZN[:, 3:])


# -- Engine's methods ---------------------------------------------------------------------------

@pytest.mark.parametrize("key, value", [("width", 0), ("height", -1), ("width", True), ("width", 2.5),
                                        ("height", 16385), ("width", "8"), ("width", np.nan)])
def test_render_size_checked(engine, key, value):
    """width=0 silently meant the camera's width; 2.5 was a pyopencl bad_cast."""
    with pytest.raises(params.ParamError, match=rf"^{key}: expected an integer in 1..16384, got"):
        engine.render(**{key: value}, photons=1000)
    with pytest.raises(params.ParamError, match=rf"^{key}: expected an integer in 1..16384"):
        engine.camera_points(**{key: value})


@pytest.mark.parametrize("value", [-1, 0, np.nan, np.inf, True, "1", 1e-300, 1e39])
def test_render_exposure_checked(engine, value):
    """Were accepted: black, or NaN, pixels."""
    with pytest.raises(params.ParamError, match=r"^exposure: expected 'auto' or a positive number from 1.2e-38 to 3.4e38"):
        engine.render(exposure=value, photons=1000)


def test_render_takes_numpy_numbers(engine):
    r = engine.render(width=np.int64(5), height=np.int32(2), exposure=np.float32(2.0), radius=np.float32(0.05),
                      photons=1000)
    assert r.radiance.shape == (2, 5, 3) and r.pixels.shape == (2, 5, 4)
    assert r.estimate.stats.radius == pytest.approx(0.05)


def test_shade_checks_its_arguments(engine):
    pts = engine.camera_points()
    est = engine.irradiance(pts, photons=1000)
    with pytest.raises(OclgiError, match=r"^shade: irradiance must be a device buffer of 12 float4 values"):
        engine.shade(pts, None)
    with pytest.raises(OclgiError, match=r"^shade: points must be a camera's QueryPoints"):
        engine.shade(QueryPoints(*packed()), est.estimator.irr)
    with pytest.raises(params.ParamError, match=r"^exposure:"):
        engine.shade(pts, est.estimator.irr, exposure=-2)
    radiance, pixels = engine.shade(pts, est.estimator.irr)
    assert radiance.shape == (3, 4, 3) and pixels.shape == (3, 4, 4)


def test_engine_and_estimator_arguments(engine):
    scene = oclgi.load_dict(DESC)
    for bad, match in ((lambda: oclgi.Engine("scene.toml"), r"^Engine takes a Scene"),
                       (lambda: oclgi.Engine(scene, progress="yes"), r"^progress: expected true or false"),
                       (lambda: oclgi.Engine(scene, device=3), r"^device must be a spec"),
                       (lambda: oclgi.Engine(scene, local_size=2.5), r"^--local-size must be a positive integer"),
                       (lambda: oclgi.Engine(scene, local_size=True), r"^--local-size must be a positive integer"),
                       (lambda: engine.estimator(QueryPoints(*packed()), "detp"), r"^estimator: params must be"),
                       (lambda: engine.estimator(XYZN, engine.run_params()), r"^points must be a QueryPoints"),
                       (lambda: engine.irradiance(XYZN, photons=1000, count_work="yes"),
                        r"^count_work: expected true or false, got 'yes'$"),
                       (lambda: engine.irradiance(None), r"^points must be an \(n, 6\) array"),
                       (lambda: engine.move(7, np.eye(4)), r"^move: the object's name must be a string"),
                       (lambda: engine.view_camera("camera"), r"^camera must be an oclgi.Camera")):
        with pytest.raises(OclgiError, match=match):
            bad()
    assert oclgi.Engine(scene, local_size=np.int64(2)).local_size == 2


def test_sessions_check_their_flags(engine):
    with pytest.raises(params.ParamError, match=r"^count_work: expected true or false, got 1$"):
        oclgi.Session(engine, XYZN, photons=1000, count_work=1)


# -- float32: the run's derived constants ---------------------------------------------------------

def test_radius_whose_resolve_underflows_is_refused(engine):
    """1 / (scale pi d^2) below float32's normal range: zero irradiance everywhere, silently."""
    with pytest.raises(OclgiError, match=r"^floor: the emitters' power .* give 1 / \(scale pi d\^2\), DETP's resolve "
                                         r"= .*, out of float32's range on the device"):
        engine.irradiance(XYZN, method="detp", photons=1000, radius=1e17)
    # the same radius means nothing to Impact Count
    assert engine.irradiance(XYZN, method="impact", photons=1000, radius=1e17).irradiance.max() > 0


def test_scene_built_in_python_is_checked_where_it_meets_the_engine():
    """A Scene made in Python skips the scene file's checks: the engine's hold."""
    scene = oclgi.load_dict(DESC)
    for emission, match in (((1e39, 1, 1), r"^material 'light': emission: expected a number from 0 to 3.4e38"),
                            ((1, 1e-40, 1), r"0 or at least 1.2e-38 in size \(float32 on the device\), got 1e-40$"),
                            ((1, np.nan, 1), r"got nan$"), ((1, True, 1), r"got True$")):
        scene.materials[-1] = oclgi.Material("light", emission=emission)
        with pytest.raises(params.ParamError, match=match):
            oclgi.Engine(scene, progress=False)
    scene.materials[-1] = oclgi.Material("light", emission=(5, 5, 5))
    scene.point_lights = [oclgi.PointLight((0, 0.5, 0), (1e38, 1, 1))]
    with pytest.raises(params.ParamError, match=r"^point light 0: power \(4 pi intensity\): expected a number"):
        oclgi.Engine(scene, progress=False)
    scene.point_lights = []
    scene.materials[-1] = oclgi.Material("light", emission=(1e-30, 0, 0))
    engine = oclgi.Engine(scene, progress=False)
    with pytest.raises(OclgiError, match=r"too small for fixed-point sums"):
        engine.irradiance(XYZN, photons=1000)
    with pytest.raises(OclgiError, match=r"too small for fixed-point sums"):
        oclgi.Session(engine, XYZN, photons=1000)


@pytest.mark.parametrize("key, value, match", [
    ("width", 2.5, r"^camera.width: expected an integer in 1..16384, got 2.5$"),  # was a pyopencl bad_cast
    ("height", True, r"^camera.height: expected an integer in 1..16384, got True$"),
    ("fov", True, r"^camera.fov: expected a number from 0 to 180, 0 or at least 1.2e-38"),
    ("fov", np.nan, r"^camera.fov: expected a number"),
    ("position", (0, 1), r"^camera.position: expected 3 finite numbers, got \(0, 1\)$"),
    ("look_at", ("a", 0, 0), r"^camera.look_at: expected 3 finite numbers"),
    ("up", (0, np.inf, 0), r"^camera.up: expected 3 finite numbers"),
])
def test_cameras_made_in_python_are_checked(engine, key, value, match):
    cam = dataclasses.replace(engine.scene.camera, **{key: value})
    with pytest.raises(params.ParamError if key in ("width", "height", "fov") else OclgiError, match=match):
        engine.render(camera=cam, photons=1000)
    good = dataclasses.replace(engine.scene.camera, width=np.int64(3), fov=np.float32(30))
    assert engine.camera_points(good).shape == (3, 3)
