"""The engine: a scene on an OpenCL device; trace, estimate, render.

>>> import oclgi
>>> scene = oclgi.load_file(oclgi.scene_path("cornell_box.toml"))
>>> engine = oclgi.Engine(scene)
>>> result = engine.render(photons=20_000, width=32, height=32)
>>> result.radiance.shape
(32, 32, 3)
>>> bool(result.radiance.max() > 0)
True
>>> result.stats.segments > result.stats.photons
True
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pyopencl as cl

from . import budget, params, queries
from .cl import constants
from .cl.device import create_context
from .cl.programs import launch, programs
from .errors import OclgiError, OclgiWarning
from .estimators import ESTIMATORS, check_options
from .estimators.gather_options import requested_rays
from .tracing.photon_trace import PhotonTracer
from .tracing.run import Estimate, PathRange, Run, Stats  # noqa: F401 (Estimate, Stats: the engine's results)
from .accel.bvh_build import QUALITIES
from .scene.compiled import BVH_QUALITY, CompiledScene
from .params import RunParams, flag, radius as read_radius
from .scene.description import load_dict, validate_camera
from .scene.mesh import is_trimesh
from .scene import lights
from .scene.scene import Camera, Scene

DEFAULT_BATCH_BYTES = 256 << 20


# params.VIEWS by the ids the tone mapping kernel takes (kernels/view_transform.h)
VIEW_IDS = {"srgb": constants.VIEW_SRGB, "agx": constants.VIEW_AGX, "filmic": constants.VIEW_FILMIC}

LAYER_CHANNELS = {"irradiance": "RGB", "albedo": "RGB", "normal": "XYZ", "depth": "Z"}


def render_layers(points, irradiance: np.ndarray, albedo: np.ndarray, camera, spp: int) -> dict:
    """A render's layers (compositing, denoisers): the irradiance E (W/m^2),
    the albedo and the normal (world space, towards the camera) of the
    visible surface, and its distance from the eye; 0 on the background.
    The visible surface is the one a camera path ends on (through mirrors
    and glass), ``albedo`` (image_shade's) its diffuse part's, textured,
    times the path's weight.
    Each the mean over a pixel's samples, as the radiance."""
    h, w = points.shape
    tri = points.tri
    hit = tri >= 0
    eye = np.asarray(camera.position, np.float64)
    depth = np.where(hit, np.linalg.norm(points.positions[:, :3].astype(np.float64) - eye, axis=1), 0.0)
    raw = {"irradiance": np.where(hit[:, None], irradiance, 0.0), "albedo": albedo,
           "normal": np.where(hit[:, None], points.normals[:, :3], 0.0), "depth": depth[:, None]}
    return {k: np.ascontiguousarray(v.astype(np.float64).reshape(spp, h // spp, w, -1).mean(axis=0), np.float32)
            for k, v in raw.items()}


def render_metadata(engine, run_params, est, camera, spp: int, exposure: float, view: str = "srgb") -> dict:
    """What made an image, as the attributes its files carry (``oclgi:``
    names, text values: PNG keeps text only): the scene, the method and its
    parameters, the photons traced, the camera, the samples per pixel,
    oclgi's version. No time stamp: the same run writes the same bytes."""
    from . import __version__

    p = asdict(run_params)
    meta = {"version": __version__, "scene": engine.scene.name, "method": p["method"],
            "photons": est.stats.photons, "segments": est.stats.segments, "seed": p["seed"],
            "radius": f"{p['radius']:.9g}", "max_depth": p["max_depth"], "extension": f"{p['extension']:.9g}",
            "count_emitted": str(p["count_emitted"]).lower(), "spp": spp,
            "exposure": exposure if isinstance(exposure, str) else f"{exposure:.9g}", "view": view}
    if camera is not None:
        meta.update({f"camera_{k}": " ".join(f"{v:.9g}" for v in getattr(camera, k))
                     for k in ("position", "look_at", "up")})
        meta["camera_fov"] = f"{camera.fov:.9g}"
    return {f"oclgi:{k}": str(v) for k, v in meta.items()}


KEY = 0.18  # middle grey: where auto exposure puts the image's log-average luminance


def auto_exposure(radiance: np.ndarray) -> float:
    """The exposure that maps the log-average luminance of the covered
    pixels (radiance (n, 4), w = coverage) to middle grey (Reinhard et al.'s
    key value 0.18); 1 for an image with no light."""
    from .photometry import luminance

    lum = luminance(radiance[:, :3])
    lit = (radiance[:, 3] > 0) & (lum > 0)
    if not lit.any():
        return 1.0
    mean = float(np.exp(np.mean(np.log(lum[lit]))))
    return float(np.clip(KEY / mean, params.F32_TINY, params.F32_MAX))


R2 = 1.32471795724474602596  # the plastic number: the R2 sequence's generator


def sample_offsets(spp: int) -> list[tuple[float, float]]:
    """Where in a pixel each of ``spp`` samples looks: the R2 low-discrepancy
    sequence from the pixel's centre (sample 0), the same for every pixel
    and every run, so images are reproducible and a sample set is a
    rotated-grid supersampling of the pixel."""
    return [((0.5 + k / R2) % 1.0, (0.5 + k / R2**2) % 1.0) for k in range(spp)]


def as_query_points(points) -> queries.QueryPoints:
    """QueryPoints as given, or from an (n, 6) array of x y z nx ny nz."""
    if isinstance(points, queries.QueryPoints):
        return points
    if points is None:
        raise OclgiError("points must be an (n, 6) array of x y z nx ny nz or a QueryPoints, got None")
    a = queries.real_array(points, "points")
    if a.ndim != 2 or a.shape[1] != 6:
        raise OclgiError(f"points must be an (n, 6) array of x y z nx ny nz, got shape {a.shape}")
    return queries.from_arrays(a[:, :3], a[:, 3:])


def _check_float32(scene: Scene) -> None:
    """The scene's radiant values as the device holds them, in float32: a
    Scene made or changed in Python has not been through the scene file's
    readers (oclgi/scene/description.py), and a value beyond float32 would
    reach the device as inf, or as 0 for one below its normal range."""
    for m in scene.materials:
        for key in ("emission", "albedo"):
            for x in np.ravel(np.asarray(getattr(m, key), dtype=object)):
                params.float32_real(x, f"material {m.name!r}: {key}", 0.0)
    for i, light in enumerate(scene.point_lights):
        for x in np.ravel(np.asarray(light.intensity, dtype=object)):
            params.float32_real(x, f"point light {i}: intensity", 0.0)
            params.float32_real(4 * math.pi * float(x), f"point light {i}: power (4 pi intensity)", 0.0)
    lights.validate(scene)  # the spot, sun and sky lights' parameters, float32 included


@dataclass
class Render:
    radiance: np.ndarray  # (H, W, 3) float32
    pixels: np.ndarray  # (H, W, 4) uint8, tone-mapped sRGB, alpha = coverage
    estimate: Estimate
    metadata: dict = field(default_factory=dict)  # how it was made: written into the image files
    layers: dict = field(default_factory=dict)  # name -> (H, W, k) float32, with render(layers=True)

    def exr_channels(self) -> tuple[np.ndarray, list[str]]:
        """The EXR's pixels and channel names: R, G, B, then each layer's
        (``irradiance.R``, ``albedo.R``, ..., ``normal.X``, ..., ``depth.Z``)."""
        names, parts = ["R", "G", "B"], [self.radiance]
        for name, a in self.layers.items():
            parts.append(a)
            names += [f"{name}.{c}" for c in LAYER_CHANNELS[name]]
        return np.ascontiguousarray(np.concatenate(parts, axis=2), np.float32), names

    @property
    def stats(self) -> Stats:
        return self.estimate.stats

    def _repr_png_(self) -> bytes:
        """The tone-mapped image, shown inline by Jupyter and IPython."""
        from .io import png_bytes

        return png_bytes(self.pixels)


class Engine:
    """A scene compiled for one OpenCL device.

    ``device``: a spec as ``oclgi info`` lists ("P:D" or a name substring);
    default OCLGI_DEVICE / PYOPENCL_CTX / the PoCL CPU device.
    ``local_size``: work-group size of the kernels (None: the runtime's
    choice); results do not depend on it.
    ``bvh``: the scene trees (oclgi/accel/bvh_build.py QUALITIES), "sah8b"
    (the default: a binned SAH tree collapsed into 8-wide nodes traversed
    with float8 slab tests, about a third of the binary tree's node visits,
    its leaves tested 4 triangles at a time), "sah" (the binary SAH tree) or
    "lbvh" (the binary tree in Morton order: a faster build, more nodes per
    ray); the hits are the same up to ties between equally near triangles.
    """

    def __init__(self, scene: Scene, device: str | None = None, local_size: int | None = None,
                 batch_bytes: int = DEFAULT_BATCH_BYTES, progress: bool | None = None, bvh: str = BVH_QUALITY):
        if is_trimesh(scene):  # a trimesh Trimesh or Scene: its meshes, materials and emission
            scene = load_dict({"name": "trimesh", "mesh": [{"trimesh": scene}]})
        if not isinstance(scene, Scene):
            raise OclgiError(f"Engine takes a Scene (oclgi.load_file, oclgi.load_dict) or a trimesh Trimesh or "
                             f"Scene, got {type(scene).__name__}")
        if device is not None and not isinstance(device, str):
            raise OclgiError(f"device must be a spec such as '0:0' or a name substring, got {device!r}")
        if progress is not None:
            progress = params.flag(progress, "progress")
        batch_bytes = params.batch_bytes(batch_bytes)
        if bvh not in QUALITIES:
            raise OclgiError(f"bvh must be one of {', '.join(QUALITIES)}, got {bvh!r}")
        _check_float32(scene)
        self.scene = scene
        self.device_spec = device  # what a process of its own opens the same device with (oclgi/viewer/render_process.py)
        self.ctx, self.queue = create_context(device)
        if local_size is not None:
            dev = self.queue.device
            limit = min(dev.max_work_group_size, dev.max_work_item_sizes[0])
            try:
                local_size = params.local_size(local_size, "--local-size")
            except params.ParamError:
                raise OclgiError(f"--local-size must be a positive integer, got {local_size!r}") from None
            if local_size > limit:
                raise OclgiError(f"--local-size {local_size} is larger than {dev.name.strip()!r} allows ({limit})")
        self.local_size = local_size
        self.batch_bytes = batch_bytes
        self.progress = progress
        t0 = time.perf_counter()
        self.compiled = CompiledScene(self.ctx, scene, bvh_quality=bvh)
        # Movable objects' world normals come from the device, as after any
        # move, so that moving back to the loaded pose gives the same bits.
        for k, obj in enumerate(scene.objects):
            if obj.movable:
                self.compiled.set_transform(self.queue, k, np.eye(4))
        self.setup_seconds = time.perf_counter() - t0
        self._programs = programs(self.ctx)

    # -- objects -----------------------------------------------------------------
    shared_by_sessions = True  # a session's close() frees its own buffers, never these (oclgi/cl/release.py)
    owner = None  # the session whose own view of the engine this is (Engine.posed)

    def move(self, name: str, matrix) -> None:
        """Place movable object ``name`` by a 4x4 (or 3x4) world-from-object
        matrix, relative to where the scene file put it (identity = back home).
        Later traces and renders of this engine see the object there; nothing
        is rebuilt but its instance record. Sessions have poses of their own
        (``Session.move``): moving the engine does not move them."""
        if self.owner is not None:
            raise OclgiError(f"this engine is the view of a {type(self.owner).__name__} at its own pose: move "
                             "objects with the session's move(), which keeps its sums up to date")
        self.place(name, matrix)

    def place(self, name: str, matrix) -> None:
        """``move`` without the owner's check: the session's own step."""
        if not isinstance(name, str):
            raise OclgiError(f"move: the object's name must be a string, got {name!r}")
        self.compiled.set_transform(self.queue, self.scene.object_id(name), matrix)

    def posed(self, owner=None) -> "Engine":
        """A view of this engine at a pose of its own, starting from this
        engine's current pose: the device, the programs and the compiled
        scene's trees and tables are shared; moves of the one do not reach
        the other (oclgi/scene/pose.py). ``owner``: the session the view
        belongs to (its ``move`` then refuses: the session moves it)."""
        view = copy.copy(self)
        view.compiled = self.compiled.at(self.compiled.pose.copy(self.queue))
        view.owner = owner
        return view

    # -- parameters (oclgi/scene_parameters.py) -------------------------------------
    def parameters(self):
        """What can change after loading (materials, lights, camera, the
        run's defaults), by name; set values, then ``update()``."""
        from .scene_parameters import Parameters

        return Parameters(self)

    def _parameter_values(self) -> dict:
        from .scene_parameters import values

        return values(self.scene, self.run_params(), self.scene.camera)

    def _apply_parameters(self, changes: dict):
        """The engine's part of an update: its scene, its tables (materials,
        lights), its run defaults. Sessions already open keep theirs."""
        from .scene_parameters import Updated, changed_scene, kinds

        t0 = time.perf_counter()
        scene, run = changed_scene(self.scene, changes)
        if run:
            scene.settings = RunParams.read(run, base=self.scene.settings)
        what = kinds(changes)
        compiled = self.compiled.with_scene(scene) if "tables" in what else self.compiled
        self.scene, self.compiled = scene, compiled
        return Updated(tables="tables" in what, seconds=time.perf_counter() - t0)

    def pose_matrix(self, name: str) -> np.ndarray:
        """Object ``name``'s current world-from-object transform (4x4)."""
        return self.compiled.pose.matrix(self.scene.object_id(name))

    # -- query points -------------------------------------------------------
    def camera_points(self, camera: Camera | None = None, width: int | None = None,
                      height: int | None = None, spp: int = 1, lift: float | None = None) -> queries.QueryPoints:
        """The visible point of every pixel; with ``spp`` > 1 samples per
        pixel, one image of points per sample (``sample_offsets``), stacked:
        shape (spp * height, width). ``lift``: the disc radius they are for
        (``view_points``; None: the scene's)."""
        cam = self.view_camera(camera, width, height)
        spp = params.samples_per_pixel(spp)
        budget.check(budget.camera_need(cam.width, cam.height * spp), self.queue.device)
        images = [self.view_points(cam, (0, 0, cam.width, cam.height), offset=o, sample=k, lift=lift)
                  for k, o in enumerate(sample_offsets(spp))]
        return images[0] if spp == 1 else queries.stack(images)

    def view_camera(self, camera: Camera | None = None, width: int | None = None,
                    height: int | None = None) -> Camera:
        """The camera given (or the scene's), resized (``width``, ``height``:
        None keeps the camera's), validated."""
        if camera is not None and not isinstance(camera, Camera):
            raise OclgiError(f"camera must be an oclgi.Camera, got {type(camera).__name__}")
        cam = camera or self.scene.camera
        if cam is None:
            raise OclgiError(f"{self.scene.name}: no [camera] in the scene")
        if camera is None and self.scene.camera_note and not getattr(self, "_camera_noted", False):
            warnings.warn(self.scene.camera_note, OclgiWarning, stacklevel=3)  # once per engine
            self._camera_noted = True
        width = None if width is None else params.image_size(width, "width")
        height = None if height is None else params.image_size(height, "height")
        return validate_camera(replace(cam, width=width or cam.width, height=height or cam.height))

    def view_points(self, cam: Camera, rect, instances=None, offset=(0.5, 0.5), sample: int = 0,
                    lift: float | None = None, first_in=None, first_out=None) -> queries.QueryPoints:
        """Visible points of the pixels of ``rect`` = (x0, y0, w, h), row-major,
        against all instances or against ``instances`` = (buffer, count), each
        through its pixel's point ``offset`` (pixel units from its corner);
        ``sample`` numbers a pixel's samples (the random numbers of its path
        through mirrors, glass and highlights, kernels/camera.cl). ``lift``:
        the disc radius the points' discs will have, how far a point with a
        shading normal is lifted (times the sine of its tilt, so its disc
        stays in front of its triangle: oclgi/scene/shading_normals.py);
        None: the scene's radius. ``first_in``, ``first_out``: device
        buffers of a float4 per pixel of the whole image, each pixel's
        first surface to go on from, and to write (kernels/camera.cl)."""
        lift = self.scene.radius if lift is None else lift
        if isinstance(lift, bool) or not isinstance(lift, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(lift) and 0 <= lift <= params.F32_MAX):
            raise OclgiError(f"lift: expected a disc radius >= 0 (a float32), got {lift!r}")
        x0, y0, rw, rh = (int(v) for v in rect)
        eye, fwd, right, up = cam.frame()
        n = rw * rh
        mf = cl.mem_flags
        pos, nrm, bary, wt = (cl.Buffer(self.ctx, mf.WRITE_ONLY, max(n, 1) * s) for s in (16, 16, 8, 16))
        k = self._programs.get("camera").camera_visible_points
        c = self.compiled
        scene_args = c.scene_args if instances is None else (c.nodes, c.tris, instances[0], int(instances[1]))
        as4 = lambda v: np.array([*v, 0.0], np.float32)  # noqa: E731
        host = tuple(np.empty((n, k_), np.float32) for k_ in (4, 4, 2, 4))
        if n:
            launch(self.queue, k, n, *scene_args, c.tri_normals, c.tri_material, c.materials, c.tri_shading,
                   c.tri_object, c.instances, as4(eye), as4(fwd), as4(right), as4(up), cam.width, cam.height,
                   x0, y0, rw, rh, np.array(offset, np.float32), int(sample), np.float32(c.eps), np.float32(lift),
                   first_in, first_out, pos, nrm, bary, wt, local_size=self.local_size)
            for h, dev in zip(host, (pos, nrm, bary, wt)):
                cl.enqueue_copy(self.queue, h, dev)
        # made once filled: QueryPoints checks its values
        return queries.QueryPoints(*host[:3], kind="camera", shape=(rh, rw), weights=host[3])

    def vertex_points(self) -> queries.QueryPoints:
        return queries.vertex_points(self.scene)

    # -- estimation -----------------------------------------------------------
    def irradiance(self, points, method: str | None = None, photons: int | None = None,
                   radius: float | None = None, seed: int | None = None, max_depth: int | None = None,
                   extension: float | None = None, count_emitted: bool | None = None,
                   count_work: bool = False, **options) -> Estimate:
        """Irradiance at query points (a QueryPoints, or an (n, 6) array x y z nx ny nz).

        ``count_work`` builds the kernels with exact work counters (returned
        in ``Estimate.work``); ``options`` go to the estimator (its own
        parameters, e.g. the sphere cache's ``q``).
        """
        run = self.run(points, method, photons, radius, seed, max_depth, extension, count_emitted,
                       count_work=count_work, **options)
        return run.complete(self.progress)

    def run(self, points, method: str | None = None, photons: int | None = None, radius: float | None = None,
            seed: int | None = None, max_depth: int | None = None, extension: float | None = None,
            count_emitted: bool | None = None, count_work: bool = False, paths: PathRange | None = None,
            **options) -> Run:
        """The run ``irradiance`` makes, not yet traced (oclgi/tracing/run.py):
        step it, save and resume its state, extend it, finish it. ``paths``:
        the range of path ids this run traces (default: all of them)."""
        points = as_query_points(points)
        r = self.run_params(method, photons, radius, seed, max_depth, extension, count_emitted)
        count_work = params.flag(count_work, "count_work")
        budget.check(budget.irradiance_need(len(points), r.method, r.photons, r.max_depth, self.batch_bytes,
                                            options.get("k"), requested_rays(options)), self.queue.device)
        est = self.estimator(points, r, count_work=count_work, **options)
        return Run(self, est, r, paths)

    def run_params(self, method=None, photons=None, radius=None, seed=None, max_depth=None, extension=None,
                   count_emitted=None) -> RunParams:
        """The parameters of a run: the given ones (those not None), else the
        scene's, checked (oclgi/params.py); the radius defaults to 1% of the
        scene's diagonal when the scene gives none."""
        given = dict(method=method, photons=photons, radius=radius, seed=seed, max_depth=max_depth,
                     extension=extension, count_emitted=count_emitted)
        run = RunParams.read({k: v for k, v in given.items() if v is not None}, base=self.scene.settings)
        if run.radius is None:
            run = replace(run, radius=read_radius(self.scene.radius, "radius (by default 1% of the scene's diagonal)"))
        return run

    def _check_precision(self, run: RunParams) -> None:
        """The run's derived constants, in the float32 the device takes them
        in: the fixed-point scale (units per watt), its inverse (Impact
        Count's and Photon Maps' resolve) and DETP's 1 / (scale pi d^2). One
        that rounds to 0 or inf in float32 would give zeros, inf or NaN
        everywhere; the scene's power, the photon count and the radius decide
        them, so this is checked where a run meets the scene (every
        estimator is made by Engine.estimator, the sessions' too), whether
        the scene came from a file or from Python."""
        scale = self.compiled.fixed_scale(run.photons)  # refuses a scale beyond float32 itself
        derived = {"1 / the fixed-point scale": 1.0 / scale}
        if ESTIMATORS[run.method].family == "detp":
            derived["1 / (scale pi d^2), DETP's resolve"] = 1.0 / (scale * math.pi * run.radius**2)
        for what, value in derived.items():
            if not params.F32_TINY <= value <= params.F32_MAX:
                raise OclgiError(f"{self.scene.name}: the emitters' power "
                                 f"({self.compiled.photon_power_max:.3g} W per photon path), {run.photons:,} "
                                 f"photons and radius {run.radius:.3g} give {what} = {value:.3g}, out of "
                                 "float32's range on the device; scale the emission or change the radius")

    def _check_points(self, points) -> None:
        """The gate every set of query points passes before a kernel reads it."""
        if not isinstance(points, queries.QueryPoints):
            raise OclgiError(f"points must be a QueryPoints, got {type(points).__name__}")
        if len(points) == 0:
            raise OclgiError("no query points given")
        points.check_triangles(self.scene.n_triangles, f"scene {self.scene.name!r}")

    def estimator(self, points, params: RunParams, count_work: bool = False, request_points: int | None = None,
                  **options):
        """A fresh estimator of ``params.method`` over ``points``; ``options``
        are the method's own (estimators.check_options checks their names).
        ``request_points``: the size of the request ``points`` are part of (a
        session's layer, default ``len(points)``), which defaults such as
        the direct light's samples are taken from."""
        if not isinstance(params, RunParams):
            raise OclgiError(f"estimator: params must be a RunParams (Engine.run_params), got {type(params).__name__}")
        cls = ESTIMATORS[params.method]
        check_options(params.method, options)
        self._check_points(points)
        self._check_precision(params)
        if getattr(cls, "radii_maker", None) is not None and options.get("radius_mode") == "adaptive" \
                and options.get("radii") is None:
            options = dict(options, pilot=self.pilot_paths(options))
        defaulted = None  # the request's points, when the direct light's samples are the default's
        if cls.family == "detp" and options.get("direct") == "exact" and options.get("direct_samples") is None:
            from .estimators.detp_direct import default_samples

            defaulted = len(points) if request_points is None else request_points
            options = dict(options, direct_samples=default_samples(params.photons, defaulted))
        est = self._new_estimator(cls, points, params, count_work, options)
        est.default_direct_points = defaulted  # a longer run (Run.extend) takes its own count's default
        return est

    def _new_estimator(self, cls, points, params: RunParams, count_work, options: dict):
        if cls.family == "detp" and options.get("gather", 0):
            from .estimators.final_gather import FinalGather
            from .estimators.gather_options import spacing
            from .estimators.irradiance_cache import IrradianceCache

            options = dict(options)
            sparse = spacing(options.get("gather_spacing", 1)) > 1
            if not sparse:
                options.pop("gather_spacing", None)
            return (IrradianceCache if sparse else FinalGather)(
                cls, self.queue, self.compiled, points, radius=params.radius, seed=params.seed,
                extension=params.extension, count_emitted=params.count_emitted, local_size=self.local_size,
                count_work=flag(count_work, "count_work"), **options)
        if cls.family == "detp":  # the exact direct light's random numbers are the run's
            options = dict(options, seed=params.seed)
        return cls(self.queue, self.compiled, points, radius=params.radius, extension=params.extension,
                   count_emitted=params.count_emitted, local_size=self.local_size,
                   count_work=flag(count_work, "count_work"), **options)

    def pilot_paths(self, options: dict):
        """The paths adaptive DETP radii are taken from
        (oclgi/estimators/adaptive_radius.py): ``pilot_photons`` of them
        from the pilot's own seed, so the radii depend on neither the run's
        seed nor its batches. The options are checked first."""
        from .estimators import adaptive_radius, radius_options

        given = {k: options.get(k, v) for k, v in radius_options.DEFAULTS.items()}
        radius_options.check(**given)
        n = int(given["pilot_photons"])
        tracer = PhotonTracer(self.queue, self.compiled, adaptive_radius.PILOT_SEED, adaptive_radius.PILOT_MAX_DEPTH,
                              n, self.local_size)
        return tracer.trace(0, n)

    def trace(self, photons: int | None = None, seed: int | None = None, max_depth: int | None = None):
        """Trace photon paths and return their segments on the host.

        Returns (segments, path_len): a ``Segment`` structured array of
        photons * max_depth slots, path-major (empty slots are zeros), and the
        number of segments of each path. Powers are in watts per channel, as
        the run's ``photons`` paths share the emitters' power (the device
        stores them in units of the largest photon power, scaled here by
        ``photon_watts``). For inspection and studies; the estimators stream
        batches instead of keeping every segment.
        """
        given = dict(photons=photons, seed=seed, max_depth=max_depth)
        run = RunParams.read({k: v for k, v in given.items() if v is not None}, base=self.scene.settings)
        photons, seed, max_depth = run.photons, run.seed, run.max_depth
        if photons * max_depth * 48 > self.batch_bytes:
            raise OclgiError(f"{photons:,} paths of up to {max_depth} segments do not fit one batch "
                             f"({self.batch_bytes >> 20} MiB); trace fewer")
        tracer = PhotonTracer(self.queue, self.compiled, seed, max_depth, photons, self.local_size)
        batch = tracer.trace(0, photons)
        segments = batch.read_segments(self.queue)
        segments["power"] *= self.photon_watts(photons)
        return segments, batch.read_path_len(self.queue)

    def photon_watts(self, photons: int) -> np.float32:
        """Watts of one device unit of power (the largest power a photon
        carries) in a run of ``photons`` paths: the device's powers (stored
        segments, a Photon Map's impacts) times this are watts."""
        return np.float32(self.compiled.photon_power_max / params.photons(photons))

    # -- images -----------------------------------------------------------------
    def render(self, camera: Camera | None = None, width: int | None = None, height: int | None = None,
               exposure: float = 1.0, layers: bool = False, view: str = "srgb", **estimate_args) -> Render:
        """Radiance image L = Le + albedo E / pi of the visible points, and its tone-mapped pixels.
        ``width``, ``height``: None for the camera's; ``spp``: samples per
        pixel; ``layers``: also irradiance, albedo, normal and depth
        (``Render.layers``, written into the EXR by ``save_render``);
        ``view``: the pixels' view transform, "srgb" (clamp, as always),
        "agx" or "filmic" (kernels/view_transform.h; the radiance is linear
        whatever the view)."""
        exposure = params.exposure(exposure, "exposure")
        layers = params.flag(layers, "layers")
        view = params.view(view)
        run = self.render_run(camera, width, height, **estimate_args)
        return self.render_result(run, run.complete(self.progress), exposure, layers, view)

    def render_run(self, camera: Camera | None = None, width: int | None = None, height: int | None = None,
                   paths: PathRange | None = None, spp: int = 1, **estimate_args) -> Run:
        """The run ``render`` makes over the camera's visible points (``spp``
        per pixel), not yet traced (``Engine.run``); ``render_result`` turns
        its estimate into the image."""
        t0 = time.perf_counter()
        cam, spp, pts = self.render_points(camera, width, height, spp, estimate_args)
        run = self.run(pts, paths=paths, **estimate_args)
        run.seconds["camera"] = time.perf_counter() - t0
        run.spp, run.camera = spp, cam
        return run

    def render_points(self, camera, width, height, spp, estimate_args: dict):
        """A render's camera (checked), samples per pixel and visible
        points, its memory checked first: (camera, spp, points)."""
        cam = self.view_camera(camera, width, height)
        spp = params.samples_per_pixel(spp)
        budget.check(self.render_need(cam, spp, estimate_args), self.queue.device)
        r = self.run_params(*(estimate_args.get(k) for k in params.RUN_KEYS))
        return cam, spp, self.camera_points(cam, spp=spp, lift=r.radius)

    def render_need(self, cam: Camera, spp: int, estimate_args: dict) -> "budget.Need":
        """The memory a render of ``cam`` at ``spp`` samples a pixel with
        ``estimate_args`` takes (its points, batches and gather rays)."""
        r = self.run_params(*(estimate_args.get(k) for k in params.RUN_KEYS))
        return budget.render_need(cam.width, cam.height * spp, r.method, r.photons, r.max_depth, self.batch_bytes,
                                  estimate_args.get("k"), requested_rays(estimate_args, spp))

    def render_result(self, run: Run, est: Estimate, exposure: float = 1.0, layers: bool = False,
                      view: str = "srgb") -> Render:
        """The image of a render run's estimate (resolved: ``Run.finish``);
        ``layers``: also the irradiance, albedo, normal and depth layers;
        ``view``: the pixels' view transform (``render``)."""
        spp, cam = run.spp, run.camera
        want = bool(layers and cam)
        radiance, pixels, albedo = self.shade_albedo(run.estimator.points, est.estimator.irr, exposure, spp, want,
                                                     view)
        extra = render_layers(run.estimator.points, est.irradiance, albedo, cam, spp) if want else {}
        return Render(radiance, pixels, est, render_metadata(self, run.params, est, cam, spp, exposure, view), extra)

    def shade(self, points: queries.QueryPoints, irradiance: cl.Buffer, exposure: float = 1.0, spp: int = 1,
              view: str = "srgb"):
        """(radiance, pixels): see ``shade_albedo``."""
        return self.shade_albedo(points, irradiance, exposure, spp, albedo=False, view=view)[:2]

    def shade_albedo(self, points: queries.QueryPoints, irradiance: cl.Buffer, exposure: float = 1.0,
                     spp: int = 1, albedo: bool = True, view: str = "srgb"):
        """Radiance L = Le + albedo E / pi of camera points and its tone-mapped
        pixels, from the irradiance (a device float4 buffer, one per point);
        with ``albedo``, each point's albedo too (the render's layer), else None.
        ``spp`` > 1: the points are ``camera_points``' stacked samples, and a
        pixel is the mean of its samples' radiance (its alpha, their coverage).
        ``view``: the pixels' view transform (params.VIEWS, kernels/view_transform.h)."""
        exposure = params.exposure(exposure, "exposure")
        view_id = VIEW_IDS[params.view(view)]
        spp = params.samples_per_pixel(spp)
        if not isinstance(points, queries.QueryPoints) or points.shape is None:
            raise OclgiError("shade: points must be a camera's QueryPoints (Engine.camera_points), with a shape")
        points.check_triangles(self.scene.n_triangles, f"scene {self.scene.name!r}")
        h, w = points.shape
        if h % spp:
            raise OclgiError(f"shade: {h} rows of points are not {spp} samples of an image")
        if not isinstance(irradiance, cl.Buffer) or irradiance.size < h * w * 16:
            raise OclgiError(f"shade: irradiance must be a device buffer of {h * w} float4 values (16 bytes each), "
                             f"got {getattr(irradiance, 'size', type(irradiance).__name__)}")
        n = h * w
        c = self.compiled
        prog = self._programs.get("image")
        mf = cl.mem_flags
        pos = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.positions)
        nrm = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.normals)
        rad = cl.Buffer(self.ctx, mf.READ_WRITE, n * 16)
        pix = cl.Buffer(self.ctx, mf.WRITE_ONLY, n * 4)
        wts = cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=points.weights4())
        alb = cl.Buffer(self.ctx, mf.WRITE_ONLY, n * 16)
        launch(self.queue, prog.image_shade, n, pos, nrm, irradiance, c.tri_material, c.materials, wts, c.instances,
               c.tri_uvmap, c.tri_colourmap, c.tri_object, c.textures, c.texels, c.background, c.background_texels,
               n, rad, alb)

        if spp > 1:  # the box filter over a pixel's samples, in a fixed order (the same bits every run)
            samples = np.empty((spp, h // spp, w, 4), np.float32)
            cl.enqueue_copy(self.queue, samples, rad)
            mean = np.ascontiguousarray(samples.astype(np.float64).mean(axis=0).astype(np.float32))
            h, n = h // spp, n // spp
            cl.enqueue_copy(self.queue, rad, mean)
        if exposure == params.AUTO:
            if spp > 1:
                image = mean.reshape(n, 4)
            else:
                image = np.empty((n, 4), np.float32)
                cl.enqueue_copy(self.queue, image, rad)
            exposure = auto_exposure(image)
        launch(self.queue, prog.image_tonemap, n, rad, n, exposure, view_id, pix)
        radiance = np.empty((h, w, 4), np.float32)
        pixels = np.empty((h, w, 4), np.uint8)
        cl.enqueue_copy(self.queue, radiance, rad)
        cl.enqueue_copy(self.queue, pixels, pix)
        if not albedo:  # a session's frame, a render without layers: no copy back
            return radiance[:, :, :3].copy(), pixels, None
        out = np.empty((len(points), 4), np.float32)  # per sample: the albedo layer averages them
        cl.enqueue_copy(self.queue, out, alb)
        return radiance[:, :, :3].copy(), pixels, out[:, :3]
