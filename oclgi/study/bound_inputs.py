"""The theoretical variance bounds of a study configuration, with their
inputs read off the scene (DESIGN.md section 3, "Efficiency"; the formulas
are in oclgi/study/bounds.py).

What is bounded. The thesis states the bounds for the estimate of the
reflected radiance, L_hat(p) = rho(p) E_hat(p) / pi (its bias is
L(p) - E[L_hat(p)]), not for the irradiance the engine returns. So the
study compares, per point and channel,

    Var(L_hat(p)) = (rho(p) / pi)^2 Var(E_hat(p))   with   bound(p),

rho(p) the albedo of the triangle under p (R_max where that is unknown,
which can only overstate the measured side). A channel or a point of zero
albedo reflects nothing: both sides are 0 and it is left out.

Inputs (each per colour channel; channels are independent transports):

- R_max: the largest albedo of the materials in use.
- Phi_T: the total emitted power (area lights pi A Le, point lights 4 pi I).
- A: the total triangle area.
- n_R: the number of photon paths traced. The bounds' Phi_T^2 / n_R is
  n_R carriers of power Phi_T / n_R each, squared and summed: in oclgi a
  path carries Phi_T / n on every segment (Russian roulette keeps grey
  powers constant), so the carriers are the paths. (DESIGN.md's cost model
  counts segments as n_R; with segments every bound here would shrink by the
  mean path length, segments / photons, which the study's table gives.)
- d: the configuration's disc radius; k: its neighbour count.
- Impact Count: N = the number of triangles, K = the largest triangle area
  over the smallest, n_va, n_vb, n_vc = the triangles around each vertex of
  the point's triangle. The formula counts the distinct triangles of the
  vertex average on a closed manifold mesh; where n_va + n_vb + n_vc - 5 < 1
  (an open quad split in two, say) it does not apply and the point has no
  bound (NaN).
- L_max: the derivations use it to bound the irradiance, E(p) <= pi L_max
  (E is the cosine-weighted integral of the arriving radiance). It is the
  larger of the largest emitted radiance and the largest reference E / pi
  at the query points. The second term matters twice: a point light has no
  finite radiance (its E / pi is the honest substitute), and inter-
  reflection can exceed the emitters (in a closed furnace of emission Le and
  albedo rho every wall sends L = Le / (1 - rho) = E / pi, twice Le at
  rho = 1/2). When the brightest spot is not among the points this under-
  states L_max (a tighter bound); pass ``l_max`` to override.

Units. As written, the bounds scale as Phi_T^2 L_max: with every emitter
scaled by c the variance scales by c^2 but the bound by c^3, so the verdict
would depend on the units of power. The bounds are homogeneous when L_max
is a radiance per watt emitted, and the study passes l_max = L_max / Phi_T:
the bound then reads (for DETP) R_max / ((1 - R_max) pi^2 d^2) L_max Phi_T / n_R,
which is also what a direct derivation gives (each crossing adds Phi_T / n
with probability E pi d^2 / Phi_T, so Var(E_hat) ~ Phi_T E / (n pi d^2)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import bounds
from ..estimators.photon_map import DEFAULT_K


@dataclass
class BoundInputs:
    r_max: np.ndarray  # (3,) per channel
    phi_total: np.ndarray  # (3,) W
    l_max: np.ndarray  # (3,) W / (m^2 sr)
    area: float  # m^2
    n_zones: int
    area_ratio: float
    valence: np.ndarray  # (V,) triangles around each vertex
    faces: np.ndarray  # (F, 3)

    def describe(self) -> str:
        fmt = lambda a: "/".join(f"{v:.4g}" for v in a)  # noqa: E731
        return (f"R_max {fmt(self.r_max)}, Phi_T {fmt(self.phi_total)} W, L_max {fmt(self.l_max)} W/m^2/sr, "
                f"A {self.area:.4g} m^2, N {self.n_zones:,} triangles, K {self.area_ratio:.4g}")


def scene_inputs(scene, reference: np.ndarray, point_emission: np.ndarray, l_max=None, r_max=None) -> BoundInputs:
    """Bound inputs of ``scene``; ``reference`` (n, 3) irradiance at the query
    points and ``point_emission`` (n, 3) their own emitted radiance feed L_max."""
    used = np.unique(scene.tri_material)
    albedo = np.array([scene.materials[i].r_max() for i in used], np.float64)  # all the light a kind sends on
    emission = np.array([scene.materials[i].emission for i in used], np.float64)
    power = scene.emitters()[5]
    areas = scene.triangle_areas()
    if l_max is None:
        ref = np.where(np.isfinite(reference), reference, 0.0)
        l_max = np.maximum(emission.max(axis=0), (ref / math.pi).max(axis=0))
        l_max = np.maximum(l_max, point_emission.max(axis=0))
    return BoundInputs(r_max=_per_channel(albedo.max(axis=0) if r_max is None else r_max),
                       phi_total=np.asarray(power, np.float64).sum(axis=0), l_max=_per_channel(l_max),
                       area=float(areas.sum()), n_zones=len(scene.faces), area_ratio=float(areas.max() / areas.min()),
                       valence=np.bincount(scene.faces.ravel(), minlength=len(scene.vertices)), faces=scene.faces)


def _per_channel(v) -> np.ndarray:
    return np.broadcast_to(np.asarray(v, np.float64), (3,)).copy()


def radiance_bound(inputs: BoundInputs, method: str, options: dict, radius: float, n_rays: int,
                   tri: np.ndarray) -> np.ndarray:
    """The bound on Var(L_hat) at each point and channel, (n, 3); NaN where
    it does not apply (zero albedo or emission in a channel, an Impact Count
    point off the mesh or on too open a mesh)."""
    n = len(tri)
    out = np.full((n, 3), np.nan)
    for c in range(3):
        r, phi, lm = float(inputs.r_max[c]), float(inputs.phi_total[c]), float(inputs.l_max[c])
        if not (r > 0 and phi > 0 and lm > 0):
            continue
        if r >= 1:  # the bounds diverge: no finite bound
            out[:, c] = np.inf
            continue
        l_per_watt = lm / phi  # module docstring, "Units"
        if method.startswith("detp"):
            out[:, c] = bounds.detp_bound(r, l_per_watt, phi, radius, n_rays)
        elif method == "photon_map":
            k = int(options.get("k", DEFAULT_K))
            out[:, c] = bounds.photon_map_bound(r, l_per_watt, phi, inputs.area, max(n_rays, k), k)
        elif method == "impact":
            out[:, c] = _impact_bounds(inputs, r, l_per_watt, phi, n_rays, tri)
    return out


def _impact_bounds(inputs, r, l_per_watt, phi, n_rays, tri) -> np.ndarray:
    out = np.full(len(tri), np.nan)
    on_mesh = tri >= 0
    around = np.zeros(len(tri), np.int64)
    around[on_mesh] = inputs.valence[inputs.faces[tri[on_mesh]]].sum(axis=1) - 5
    # the bound depends on the point only through the count around its triangle
    for count in np.unique(around[on_mesh & (around >= 1)]):
        nv = int(count) + 5  # any split of the sum gives the same value
        out[on_mesh & (around == count)] = bounds.impact_count_bound(
            r, l_per_watt, phi, inputs.area, n_rays, inputs.n_zones, inputs.area_ratio, nv - 2, 1, 1)
    return out
