"""The materials' scattering on the device (kernels/bsdf.h through
kernels/bsdf_probe.cl), checked per kind: the sampled directions against
the pdf (chi-square, tests/chi2.py), sample weight = f cos / pdf,
reciprocity, the white furnace and the photon weight bound, and for the
delta kinds the laws of reflection, Snell and Fresnel."""

from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from chi2 import cell_of, chi2_pvalue, expected_counts, sidak
from oclgi.cl.programs import programs
from oclgi.scene.materials import Material, record
from reference import fresnel_dielectric

N_Z, N_PHI = 32, 64
N_SAMPLES = 400_000
NORMAL = np.array([0.0, 0.0, 1.0, 0.0], np.float32)

GLOSSY = {
    "diffuse": Material("diffuse", albedo=(0.8, 0.6, 0.4)),
    "phong_n5": Material("phong_n5", kind="phong", albedo=(0.3, 0.3, 0.3), specular=(0.5, 0.4, 0.3), exponent=5.0),
    "phong_n60": Material("phong_n60", kind="phong", albedo=(0.2, 0.1, 0.1), specular=(0.7, 0.7, 0.7), exponent=60.0),
    "conductor_a0.1": Material("conductor_a0.1", kind="conductor", specular=(0.9, 0.8, 0.7), roughness=0.1),
    "conductor_a0.5": Material("conductor_a0.5", kind="conductor", specular=(1.0, 1.0, 1.0), roughness=0.5),
    "rough_glass_a0.2": Material("rough_glass_a0.2", kind="rough_dielectric", ior=1.5, roughness=0.2),
    "rough_glass_a0.6": Material("rough_glass_a0.6", kind="rough_dielectric", ior=1.33, roughness=0.6,
                                 transmission=(0.9, 0.9, 0.9)),
}
# wo by its angle from the normal, degrees; > 90 is below the surface
# (inside a dielectric, or the back of a two-sided reflector)
ANGLES = (10.0, 60.0, 85.0, 130.0)
CASES = [(name, a) for name in GLOSSY for a in ANGLES]


class Probe:
    def __init__(self, ctx, queue):
        self.ctx, self.queue = ctx, queue
        self.prog = programs(ctx).get("bsdf_probe")

    def _buf(self, a):
        return cl.Buffer(self.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    def sample(self, mat: Material, wo: np.ndarray, u: np.ndarray, adjoint: int = 1):
        n = len(u)
        wo4 = np.zeros((n, 4), np.float32)
        wo4[:, :3] = wo
        wi = np.empty((n, 4), np.float32)
        weight = np.empty((n, 4), np.float32)
        bwi, bw = (cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY, n * 16) for _ in range(2))
        self.prog.bsdf_probe_sample(self.queue, (n,), None, self._buf(record([mat])), NORMAL, self._buf(wo4),
                                    self._buf(u.astype(np.float32)), np.int32(adjoint), np.int32(n), bwi, bw)
        cl.enqueue_copy(self.queue, wi, bwi)
        cl.enqueue_copy(self.queue, weight, bw)
        return wi[:, :3].astype(np.float64), wi[:, 3].view(np.int32), weight[:, :3].astype(np.float64)

    def eval(self, mat: Material, wo: np.ndarray, wi: np.ndarray, adjoint: int = 1):
        n = len(wi)
        a, b = np.zeros((n, 4), np.float32), np.zeros((n, 4), np.float32)
        a[:, :3] = wo
        b[:, :3] = wi
        out = np.empty((n, 4), np.float32)
        bo = cl.Buffer(self.ctx, cl.mem_flags.WRITE_ONLY, n * 16)
        self.prog.bsdf_probe_eval(self.queue, (n,), None, self._buf(record([mat])), NORMAL, self._buf(a),
                                  self._buf(b), np.int32(adjoint), np.int32(n), bo)
        cl.enqueue_copy(self.queue, out, bo)
        return out[:, :3].astype(np.float64), out[:, 3].astype(np.float64)


@pytest.fixture(scope="module")
def probe(cl_env):
    return Probe(*cl_env)


def direction(deg: float) -> np.ndarray:
    t = np.radians(deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def uniform(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random((n, 4))


def chi2_test(probe, mat, wo, pdf_of):
    """(p-value, dof) of ``mat``'s sampled directions at ``wo`` against the
    pdf of material ``pdf_of``."""
    wi, _, weight = probe.sample(mat, np.tile(wo, (N_SAMPLES, 1)), uniform(N_SAMPLES, 7))
    valid = weight.max(axis=1) > 0
    expected = expected_counts(lambda d: probe.eval(pdf_of, np.tile(wo, (len(d), 1)), d)[1], N_Z, N_PHI, N_SAMPLES)
    # the absorbed samples are a cell of their own: the pdf's missing mass
    observed = np.append(np.bincount(cell_of(wi[valid], N_Z, N_PHI), minlength=N_Z * N_PHI), (~valid).sum())
    return chi2_pvalue(observed, np.append(expected, max(N_SAMPLES - expected.sum(), 0.0)))


@pytest.mark.parametrize("name,angle", CASES, ids=[f"{n}-{a:g}" for n, a in CASES])
def test_sampled_directions_follow_the_pdf(probe, name, angle):
    p, dof = chi2_test(probe, GLOSSY[name], direction(angle), GLOSSY[name])
    assert p > sidak(0.01, len(CASES)), f"{name} at {angle} deg: chi-square p = {p:.3g} ({dof} dof)"


@pytest.mark.parametrize("name", GLOSSY)
@pytest.mark.parametrize("adjoint", [1, 0])
def test_sample_weight_is_f_cos_over_pdf(probe, name, adjoint):
    mat = GLOSSY[name]
    rng = np.random.default_rng(3)
    n = 20_000
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi, flags, weight = probe.sample(mat, wo, rng.random((n, 4)), adjoint)
    valid = weight.max(axis=1) > 0
    assert valid.mean() > 0.2
    f, pdf = probe.eval(mat, wo[valid], wi[valid], adjoint)
    expect = f * np.abs(wi[valid, 2:3]) / pdf[:, None]
    ok = pdf > 1e-3  # far from float32's underflow of D and pdf
    np.testing.assert_allclose(weight[valid][ok], expect[ok], rtol=2e-3, atol=1e-5)


@pytest.mark.parametrize("name", GLOSSY)
def test_eval_is_reciprocal(probe, name):
    """f(wo, wi) = f(wi, wo) for reflection; through a refraction the
    adjoint's f(wo, wi) equals radiance's f(wi, wo) (Veach, section 5.2)."""
    mat = GLOSSY[name]
    rng = np.random.default_rng(5)
    n = 5_000
    a, b = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    f_ab, _ = probe.eval(mat, a, b, 1)
    f_ba, _ = probe.eval(mat, b, a, 0)
    assert (f_ab > 0).any()
    # float32: the transmission term cancels near grazing angles (0.3% seen)
    np.testing.assert_allclose(f_ab, f_ba, rtol=1e-2, atol=1e-6)


@pytest.mark.parametrize("name", [*GLOSSY, "mirror", "glass"])
def test_white_furnace_and_the_photon_bound(probe, name):
    """With albedo 1, a lossless kind returns all the light it receives
    (mean weight 1), the others less; no photon's weight exceeds 1 (the
    fixed-point bound, kernels/oclgi_types.h)."""
    white = {"diffuse": Material("w", albedo=(1.0, 1.0, 1.0)), "mirror": Material("w", kind="mirror"),
             "glass": Material("w", kind="dielectric", ior=1.5)}
    mat = white.get(name) or GLOSSY[name]
    lossless = name in white
    n = 200_000
    for angle in (5.0, 45.0, 80.0, 120.0, 175.0):
        _, _, weight = probe.sample(mat, np.tile(direction(angle), (n, 1)), uniform(n, int(angle)), 1)
        assert weight.max() <= 1.0 + 1e-5, f"{name}: a photon gains power ({weight.max()})"
        mean = weight.mean(axis=0)
        if lossless:
            np.testing.assert_allclose(mean, 1.0, rtol=1e-6, err_msg=f"{name} at {angle}")
        else:
            assert (mean <= 1.0 + 3e-3).all(), f"{name} at {angle}: returns more than it receives ({mean})"


def test_mirror_reflects_by_the_law_of_reflection(probe):
    mat = Material("m", kind="mirror", specular=(0.9, 0.5, 0.2))
    wo = direction(35.0)
    wi, flags, weight = probe.sample(mat, np.tile(wo, (100, 1)), uniform(100, 1))
    np.testing.assert_allclose(wi, np.tile([-wo[0], 0, wo[2]], (100, 1)), atol=1e-6)
    np.testing.assert_allclose(weight, np.tile([0.9, 0.5, 0.2], (100, 1)), rtol=1e-6)
    f, pdf = probe.eval(mat, np.tile(wo, (100, 1)), wi)
    assert (f == 0).all() and (pdf == 0).all()  # a delta has no density


@pytest.mark.parametrize("angle,ior", [(30.0, 1.5), (70.0, 1.5), (150.0, 1.5), (140.0, 1.33), (20.0, 2.5)])
def test_glass_follows_snell_and_fresnel(probe, angle, ior):
    mat = Material("g", kind="dielectric", ior=ior)
    wo = direction(angle)
    n = 200_000
    wi, flags, weight = probe.sample(mat, np.tile(wo, (n, 1)), uniform(n, 11), 1)
    entering = wo[2] > 0
    eta = ior if entering else 1 / ior
    cos_i = abs(wo[2])
    refracted = np.sign(wi[:, 2]) != np.sign(wo[2])
    F = fresnel_dielectric(cos_i, eta)
    sigma = np.sqrt(F * (1 - F) / n) + 1e-9
    assert abs((~refracted).mean() - F) < 5 * sigma + 1e-6, f"reflected {(~refracted).mean():.4f}, Fresnel {F:.4f}"
    if refracted.any():  # Snell: sin_t = sin_i / eta, in the plane of incidence, on the far side
        sin_t = np.hypot(wi[refracted, 0], wi[refracted, 1])
        np.testing.assert_allclose(sin_t, np.sqrt(1 - cos_i ** 2) / eta, rtol=1e-4)
        assert (np.sign(wi[refracted, 0]) == -np.sign(wo[0])).all()
    np.testing.assert_allclose(wi[~refracted], np.tile([-wo[0], 0, wo[2]], ((~refracted).sum(), 1)), atol=1e-5)
    # radiance through a refraction is scaled by 1 / eta^2, power is not
    _, _, w_rad = probe.sample(mat, np.tile(wo, (n, 1)), uniform(n, 11), 0)
    if refracted.any():
        np.testing.assert_allclose(w_rad[refracted], weight[refracted] / eta ** 2, rtol=1e-5)


def test_total_internal_reflection(probe):
    mat = Material("g", kind="dielectric", ior=1.5)
    wo = direction(180.0 - 60.0)  # inside, 60 degrees from the normal: past the critical 41.8
    wi, _, weight = probe.sample(mat, np.tile(wo, (1000, 1)), uniform(1000, 2))
    assert (np.sign(wi[:, 2]) == np.sign(wo[2])).all()
    np.testing.assert_allclose(weight, 1.0)


def test_one_sided_surfaces_are_black_behind(probe):
    for kind in ("diffuse", "mirror", "conductor"):
        mat = Material("o", kind=kind, albedo=(0.8, 0.8, 0.8), twosided=False)
        _, _, w_front = probe.sample(mat, np.tile(direction(30.0), (1000, 1)), uniform(1000, 4))
        _, _, w_back = probe.sample(mat, np.tile(direction(150.0), (1000, 1)), uniform(1000, 4))
        assert w_front.max() > 0 and w_back.max() == 0, kind


def test_the_chi_square_test_sees_a_wrong_pdf(probe):
    """The test above has power: samples of GGX alpha 0.1 fail against the
    pdf of alpha 0.11."""
    other = Material("other", kind="conductor", specular=(0.9, 0.8, 0.7), roughness=0.11)
    p, _ = chi2_test(probe, GLOSSY["conductor_a0.1"], direction(40.0), other)
    assert p < 1e-6
