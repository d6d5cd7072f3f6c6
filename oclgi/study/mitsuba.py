"""Mitsuba 3 as an independent reference: the same scene, path traced.

An optional reference for the estimator study and the benchmarks, never used
by the engine itself. Mitsuba is imported inside the functions only; without
it they raise one line asking for ``pip install 'oclgi[mitsuba]'``.

Conventions, as the engine and its kernels define them, and how each is
carried over:

* Geometry: every triangle where the engine sees it. Static triangles are in
  world space as loaded; a movable object's triangles go through its current
  world-from-object transform (``engine.compiled.instances_host``), so pass
  the engine rather than the scene after ``engine.move``. One Mitsuba mesh
  per (object, material), without vertex normals, so Mitsuba's face normal
  is ``(v1 - v0) x (v2 - v0)`` like oclgi's.
* Materials: each kind as its Mitsuba plugin
  (:func:`oclgi.scene.materials.to_mitsuba`): ``diffuse``, ``conductor``
  and ``roughconductor`` (GGX, ``material = "none"``: F = the specular
  reflectance at every angle), ``dielectric`` and ``roughdielectric``
  (GGX), wrapped in ``twosided`` where the material reflects on both faces;
  modified Phong, which Mitsuba 3 lacks, as a blend of a diffuse and a GGX
  lobe of about its width (an approximation).
* Emission: a material's ``emission`` is a radiance ``Le`` leaving only the
  side of the triangle's normal (the tracer emits ``pi A Le`` watts,
  cosine-distributed about the normal; the camera adds ``Le`` only where the
  normal faces it): Mitsuba's ``area`` emitter, one-sided about the same
  face normal, with ``radiance = Le``.
* The other lights (:mod:`oclgi.scene.lights`, each kind's ``to_mitsuba``):
  a point light (``intensity`` in W/sr, power ``4 pi I``) is Mitsuba's
  ``point`` with the same ``intensity``; a spot light Mitsuba's ``spot``
  (the same axis intensity and cone; in the falloff band Mitsuba ramps
  linearly in the angle where oclgi follows pbrt's smoothstep in its
  cosine); a sun Mitsuba's ``directional`` with the same ``irradiance``; a
  sky over every direction ``constant``, one over the upper hemisphere an
  ``envmap`` black below the horizon; an environment map Mitsuba's
  ``envmap`` of the same image (oclgi uses Mitsuba's orientation; Mitsuba
  filters the texels bilinearly, oclgi holds each constant).
* Camera: ``fov`` is the *vertical* field of view (``Camera.frame`` scales
  the up vector by ``tan(fov / 2)`` and the right vector by the aspect
  ratio), so Mitsuba's ``fov_axis = "y"``; rows run top to bottom and x to
  the right in both. oclgi samples each pixel at its centre only; Mitsuba
  averages over the pixel (box filter), which differs only where the
  radiance changes within a pixel, i.e. at edges, which comparisons mask
  (:mod:`oclgi.study.image_compare`).
* Path length. An oclgi photon path has at most ``max_depth`` segments, the
  first leaving the light; with ``count_emitted`` every segment, that first
  one included, adds to the irradiance ``E`` of the discs it crosses. So
  ``E`` holds the light that reached the point in at most ``max_depth``
  segments, and the image's ``L = Le + albedo E / pi`` adds one more
  segment, the one to the camera. Mitsuba's ``max_depth`` counts the
  segments of the whole path from the camera (1: emitters seen directly, 2:
  direct lighting), so the matching value is ``max_depth + 1``. The
  irradiance below is measured through one camera segment as well (see
  :func:`irradiance`), so it uses ``max_depth + 1`` too. Both renderers stop
  paths with Russian roulette without bias, so the expected values agree.
  ``count_emitted = false`` (indirect light only) has no Mitsuba
  counterpart.

Variant: ``scalar_rgb`` by default (the reference needs no JIT compiler).
``OCLGI_MITSUBA_VARIANT`` (or ``variant=``) chooses another, e.g.
``llvm_ad_rgb``, which is much faster but needs an LLVM whose x86 back end
selects ``llvm.minimum`` (LLVM 14 and 15 abort the process on Mitsuba's path
integrator).
"""

from __future__ import annotations

import math
import os

import numpy as np

from .. import params
from ..scene.materials import Material, to_mitsuba
from ..errors import OclgiError
from ..scene import lights

DEFAULT_VARIANT = "scalar_rgb"
INSTALL_HINT = "pip install 'oclgi[mitsuba]'"
# Correlated multi-jittered samples: about 1.5x less pixel noise than
# independent ones at equal spp on the Cornell box, and each seed a fresh
# randomisation (two seeds measure the noise). It stratifies on a grid, so
# spp is rounded up to a square (see sample_count).
SAMPLER = "multijitter"


def load_mitsuba(variant: str | None = None):
    """The ``mitsuba`` module with ``variant`` set (default: OCLGI_MITSUBA_VARIANT or scalar_rgb)."""
    try:
        import mitsuba as mi
    except ImportError:
        raise OclgiError(f"the Mitsuba 3 reference needs the mitsuba package: {INSTALL_HINT}") from None
    variant = variant or os.environ.get("OCLGI_MITSUBA_VARIANT") or DEFAULT_VARIANT
    if variant not in mi.variants():
        raise OclgiError(f"Mitsuba variant {variant!r} is not available (available: {', '.join(mi.variants())})")
    if mi.variant() != variant:
        mi.set_variant(variant)
    return mi


def _split(scene_or_engine):
    """(scene, engine or None) from a Scene or an Engine."""
    from ..scene.scene import Scene

    if isinstance(scene_or_engine, Scene):
        return scene_or_engine, None
    scene = getattr(scene_or_engine, "scene", None)
    if isinstance(scene, Scene) and hasattr(scene_or_engine, "compiled"):
        return scene, scene_or_engine
    raise OclgiError(f"expected an oclgi Scene or Engine, got {type(scene_or_engine).__name__}")


def world_triangles(scene_or_engine) -> np.ndarray:
    """(F, 3, 3) float64: every triangle's vertices where the engine sees them.

    For an Engine, movable objects go through their current transform; a
    Scene is taken as loaded (every object at home).
    """
    scene, engine = _split(scene_or_engine)
    tri = scene.vertices[scene.faces]
    return tri if engine is None else _placed(engine, tri, lambda t, m: t @ m[:, :3].T + m[:, 3])


def world_vertex_normals(scene_or_engine) -> np.ndarray | None:
    """(F, 3, 3): the scene's vertex normals (NaN where a triangle has none)
    turned as ``world_triangles`` places the triangles, or None."""
    from ..scene.mesh import transform_normals

    scene, engine = _split(scene_or_engine)
    vn = scene.tri_vertex_normals
    return vn if vn is None or engine is None else _placed(engine, vn, lambda n, m: transform_normals(n, m[:, :3]))


def _placed(engine, per_triangle: np.ndarray, move) -> np.ndarray:
    """A copy of ``per_triangle`` with each moved object's rows through
    ``move(rows, m)``, m its current world-from-object transform (3x4)."""
    out = per_triangle.copy()
    inst = engine.compiled.instances_host
    for k, (a, b) in enumerate(engine.scene.object_ranges()):
        m = np.asarray(inst[k]["world_from_object"], dtype=np.float64)
        if not np.array_equal(m, np.eye(4)[:3]):
            out[a:b] = move(out[a:b], m)
    return out


def max_depth_for(oclgi_max_depth: int) -> int:
    """Mitsuba's ``max_depth`` matching oclgi's ``photons.max_depth`` (see the module docstring)."""
    return int(oclgi_max_depth) + 1


def _mesh(mi, name, tris, bsdf, emitter=None, uv=None, colour=None, normals=None):
    """A Mitsuba mesh of separate triangles (F, 3, 3); ``uv`` (F, 3, 2):
    texture coordinates, v up as in OBJ and oclgi (Mitsuba's v points down
    the image: 1 - v); ``normals`` (F, 3, 3): vertex normals (shading), else
    none (flat)."""
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    n = len(tris)
    mesh = mi.Mesh(name, 3 * n, n, props=props, has_vertex_normals=normals is not None,
                   has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = type(params["vertex_positions"])(
        np.ascontiguousarray(tris, dtype=np.float32).ravel())
    if normals is not None:
        params["vertex_normals"] = type(params["vertex_normals"])(
            np.ascontiguousarray(normals, dtype=np.float32).ravel())
    if colour is not None:  # corner colours times the albedo: the reflectance (_bsdf)
        mesh.add_attribute("vertex_color", 3, np.ascontiguousarray(colour, np.float32).ravel())
    if uv is not None:
        flipped = np.stack([uv[..., 0], 1.0 - uv[..., 1]], axis=-1)
        params["vertex_texcoords"] = type(params["vertex_texcoords"])(
            np.ascontiguousarray(np.nan_to_num(flipped), dtype=np.float32).ravel())
    params["faces"] = type(params["faces"])(np.arange(3 * n, dtype=np.uint32))
    params.update()
    return mesh


def _bsdf(mi, material: Material):
    d = to_mitsuba(material)
    inner = d["bsdf"] if d["type"] == "twosided" else d
    if material.vertex_colours:
        if material.texture is not None:
            raise OclgiError(f"material {material.name!r}: the Mitsuba conversion takes a texture or vertex "
                             "colours, not both")
        inner["reflectance"] = {"type": "mesh_attribute", "name": "vertex_color"}
    if material.texture is not None:  # albedo x texture (linear), looked up as oclgi does
        pixels = np.ascontiguousarray(material.texture * np.asarray(material.albedo, np.float32))
        inner["reflectance"] = {"type": "bitmap", "bitmap": mi.Bitmap(pixels), "raw": True,
                                "filter_type": "bilinear", "wrap_mode": "repeat"}
    return mi.load_dict(d)


def scene_dict(mi, scene_or_engine) -> dict:
    """The shapes and emitters of the scene as a Mitsuba scene dict (no sensor, no integrator)."""
    scene, _ = _split(scene_or_engine)
    tris = world_triangles(scene_or_engine)
    vn = world_vertex_normals(scene_or_engine)
    out = {"type": "scene"}
    for obj in range(len(scene.objects)):
        for mat_id in np.unique(scene.tri_material[scene.tri_object == obj]):
            sel = (scene.tri_object == obj) & (scene.tri_material == mat_id)
            m = scene.materials[mat_id]
            emitter = None
            if max(m.emission) > 0:
                emitter = mi.load_dict({"type": "area",
                                        "radiance": {"type": "rgb", "value": [float(c) for c in m.emission]}})
            name = f"mesh_{obj}_{mat_id}"
            uv = scene.tri_uv[sel] if scene.tri_uv is not None and m.texture is not None else None
            colour = None
            if m.vertex_colours and scene.tri_colour is not None:
                colour = np.where(np.isnan(scene.tri_colour[sel]), 1.0, scene.tri_colour[sel]) * np.asarray(m.albedo)
            # oclgi shades with vertex normals where its camera paths end, on diffuse surfaces
            # (oclgi/scene/shading_normals.py); mirrors, glass and glossy lobes stay flat there
            normals = None
            if vn is not None and m.kind == "diffuse" and np.isfinite(vn[sel]).any():
                t = tris[sel]
                flat = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
                flat /= np.linalg.norm(flat, axis=1, keepdims=True)  # a flat triangle's three corners
                normals = np.where(np.isfinite(vn[sel]), vn[sel], flat[:, None, :])
            out[name] = _mesh(mi, name, tris[sel], _bsdf(mi, m), emitter, uv, colour, normals)
    out.update(lights.mitsuba_emitters(mi, scene))
    return out


def sample_count(spp) -> int:
    """The samples per pixel (or per point) actually taken for ``spp``: the
    next perfect square, the grid the sampler stratifies (256 and 1024 stay)."""
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise OclgiError(f"samples per pixel must be a positive integer, got {spp!r}")
    return (math.isqrt(int(spp) - 1) + 1) ** 2


def _check_seed(seed):
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise OclgiError(f"seed must be an integer in 0..2^32-1, got {seed!r}")
    return int(seed)


def _mitsuba_depth(scene, max_depth):
    if max_depth is None:
        max_depth = scene.settings.max_depth
    return max_depth_for(params.max_depth(max_depth))  # oclgi's max_depth, checked as for a run


def render(scene, camera=None, width=None, height=None, spp=256, seed=0, max_depth=None,
           variant=None) -> np.ndarray:
    """Linear radiance (H, W, 3) float32 path traced by Mitsuba at oclgi's camera.

    ``scene``: an oclgi Scene or Engine (an Engine after moves: see
    :func:`world_triangles`). ``camera`` defaults to the scene's;
    ``width``/``height`` override its resolution. ``max_depth`` is oclgi's
    (segments of a photon path, default the scene's ``photons.max_depth``).
    ``spp`` is rounded up to a square (:func:`sample_count`).
    """
    from ..scene.description import validate_camera
    from ..scene.scene import Camera

    sc, _ = _split(scene)
    cam = camera or sc.camera
    if cam is None:
        raise OclgiError(f"{sc.name}: no [camera] in the scene")
    if width or height:
        cam = Camera(cam.position, cam.look_at, cam.up, cam.fov, width or cam.width, height or cam.height)
    cam = validate_camera(cam)
    spp, seed = sample_count(spp), _check_seed(seed)
    mi = load_mitsuba(variant)
    d = scene_dict(mi, scene)
    d["integrator"] = {"type": "path", "max_depth": _mitsuba_depth(sc, max_depth)}
    d["sensor"] = {
        "type": "perspective",
        "fov": float(cam.fov),
        "fov_axis": "y",
        "near_clip": 1e-4 * sc.diagonal,
        "far_clip": 1e4 * sc.diagonal,
        "to_world": mi.ScalarTransform4f().look_at(origin=[float(c) for c in cam.position],
                                                  target=[float(c) for c in cam.look_at],
                                                  up=[float(c) for c in cam.up]),
        "film": {"type": "hdrfilm", "width": int(cam.width), "height": int(cam.height),
                 "rfilter": {"type": "box"}, "pixel_format": "rgb", "component_format": "float32"},
        "sampler": {"type": SAMPLER, "sample_count": spp},
    }
    img = mi.render(mi.load_dict(d), spp=spp, seed=seed)
    return np.array(img, dtype=np.float32).reshape(cam.height, cam.width, 3)


def irradiance(scene, positions, normals, spp=4096, seed=0, max_depth=None, variant=None) -> np.ndarray:
    """Irradiance (n, 3) float64 at points with normals, light arriving on the normal's side.

    How: a small white (albedo 1) Lambertian square is laid at each point,
    facing along its normal, and a ``radiancemeter`` looks straight down on
    it; the square reflects ``L = E / pi``, so ``E = pi L``. Unlike an
    ``irradiancemeter`` (cosine-sampled rays leaving the point), the path
    tracer samples the lights at the square (next-event estimation), which
    also catches point lights and keeps direct light from small emitters
    cheap. The squares (side 2e-4 of the scene diagonal, raised 1e-4 of it)
    shade nothing measurable; a point with other geometry within 1e-3 of
    the diagonal along its normal is an error. All points share one Mitsuba
    scene; each is rendered with ``spp`` paths (rounded up to a square) of
    its own sensor. ``max_depth`` is oclgi's: the segment to the square plays
    the camera's, so Mitsuba gets ``max_depth + 1``.
    """
    from ..queries import from_arrays

    sc, _ = _split(scene)
    q = from_arrays(positions, normals)  # validates: finite points, non-zero normals
    p = q.xyz.astype(np.float64)
    n = q.normals[:, :3].astype(np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    spp, seed = sample_count(spp), _check_seed(seed)
    mi = load_mitsuba(variant)
    diag = sc.diagonal
    half, lift, above = 1e-4 * diag, 1e-4 * diag, 1e-3 * diag

    # One square (two triangles) per point, wound so that its face normal is n.
    t = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(n, t)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)  # (u, v, n) right-handed: u x v = n
    c = p + lift * n
    corners = [c + half * (su * u + sv * v) for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    squares = np.stack([np.stack([corners[0], corners[1], corners[2]], 1),
                        np.stack([corners[0], corners[2], corners[3]], 1)], 1).reshape(-1, 3, 3)

    d = scene_dict(mi, scene)
    d["integrator"] = {"type": "path", "max_depth": _mitsuba_depth(sc, max_depth)}
    d["oclgi_sensor_squares"] = _mesh(mi, "oclgi_sensor_squares", squares,
                                      _bsdf(mi, Material("oclgi_sensor", albedo=(1.0, 1.0, 1.0), twosided=False)))
    mscene = mi.load_dict(d)
    film = {"type": "hdrfilm", "width": 1, "height": 1, "rfilter": {"type": "box"},
            "pixel_format": "rgb", "component_format": "float32"}
    out = np.empty((len(p), 3), np.float64)
    for i in range(len(p)):
        # A sensor need not belong to the scene it renders: one at a time keeps
        # the order plain (Mitsuba does not keep dict keys as sensor ids).
        sensor = mi.load_dict({"type": "radiancemeter", "origin": [float(x) for x in c[i] + above * n[i]],
                               "direction": [float(x) for x in -n[i]], "film": film,
                               "sampler": {"type": SAMPLER, "sample_count": spp}})
        _check_sees_square(mscene, sensor, above, i)
        img = mi.render(mscene, sensor=sensor, spp=spp, seed=(seed * 0x9E3779B1 + i) % 2**32)
        out[i] = math.pi * np.array(img, dtype=np.float64).reshape(3)
    return out


def _check_sees_square(mscene, sensor, distance, i):
    """The sensor's ray must meet point i's own square first (2i or 2i+1 of
    the squares mesh, at the distance it was placed), not other geometry."""
    ray, _ = sensor.sample_ray(0.0, 0.5, [0.5, 0.5], [0.5, 0.5])
    si = mscene.ray_intersect(ray)
    t = float(np.asarray(si.t).reshape(-1)[0])
    prim = int(np.asarray(si.prim_index).reshape(-1)[0])
    # Mitsuba's ray offset shortens t by ~1e-4 absolute: only a gross mismatch counts.
    if not (abs(t - distance) <= 0.5 * distance and prim // 2 == i):
        raise OclgiError(f"point {i}: other geometry lies within {distance:.3g} of it along its normal; "
                         "its irradiance cannot be measured there")
