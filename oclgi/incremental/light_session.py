"""A session whose light moves: path reuse among an animation's positions,
recomputation anywhere else (and it says which).

The light-reuse store (oclgi/tracing/light_reuse.py, Sbert, Szecsi and
Szirmay-Kalos 2004) holds the paths of every precomputed light position
from their first hits on; a frame at one of those positions connects the
light to every stored first hit, weights by the balance heuristic and sums
the tails: no ray is traced. So dragging a light along its path (a slider
over the positions, a light-path key in a viewer) costs one pass over the
store. A position that is not one of them cannot reuse the store: the
session then traces an ordinary run of the frame's photon count with the
light there, and its ``LightUpdate`` says ``reused=False``.

The session follows the protocol of the others (oclgi/incremental/protocol.py)
where it applies: ``irradiance``, ``render``, ``set_camera``,
``set_estimator``, ``close``; ``move_light`` takes the place of ``move``
(objects stay where they are: the stored paths are the animation's).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from ..engine import as_query_points
from ..errors import OclgiError
from .protocol import SessionBase


@dataclass
class LightUpdate:
    reused: bool  # by path reuse (a precomputed position), else recomputed
    frame: int | None  # the precomputed position's index, None for another
    paths_traced: int = 0  # photon paths traced (0 when reused)
    seconds: dict = field(default_factory=dict)


class LightSession(SessionBase):
    """``light``, ``positions`` (F, 3; default: the light's ``path`` in the
    scene file, one position a keyframe), ``directions``, ``photons`` (per
    position), ``seed``, ``max_depth``: as for ``LightReuse``; ``points``
    fixed query points or None for ``camera``'s view (the scene's by
    default); ``method``, ``radius`` and ``options`` the estimator's (any
    DETP variant, Impact Count or Photon Maps: each frame is a fresh sum
    over the frame's paths). Starts at position 0."""

    def __init__(self, engine, points=None, light=None, positions=None, directions=None, photons=None, seed=None,
                 max_depth=None, method=None, radius=None, camera=None, **options):
        from ..tracing.light_reuse import LightReuse, find_light

        if positions is None:  # the light's own path, from the scene file
            _, found = find_light(engine.scene, 0 if light is None else light)
            if found.path is None:
                raise OclgiError("a light session needs the light's positions (an (F, 3) array), or a light with "
                                 "a path in the scene file")
            keys = np.array(found.path, np.float64)
            positions, directions = keys[:, :3], (keys[:, 3:] if keys.shape[1] == 6 else directions)
        self.engine = engine.posed(owner=self)
        self.queue = engine.queue
        self.camera = None
        self.reuse = LightReuse(self.engine, 0 if light is None else light, positions, directions, photons, seed,
                                max_depth)
        self.points = self._points(points, camera)
        self.method, self.radius, self.options = method, radius, dict(options)
        self._set_estimator(self.reuse.estimator(self.points, method, radius, **options))
        self.params = self.reuse.run_params
        self.frame = None
        self.move_light(self.reuse.positions[0], None if self.reuse.directions is None else self.reuse.directions[0])

    def _points(self, points, camera):
        if points is not None:
            return as_query_points(points).copy()
        cam = self.engine.view_camera(camera)
        self.camera = cam
        return self.engine.view_points(cam, (0, 0, cam.width, cam.height))

    # -- moving the light ---------------------------------------------------------------
    def frame_of(self, position, direction=None) -> int | None:
        """The precomputed position equal to ``position`` (and ``direction``
        for a spot) in the float32 the device holds, or None."""
        p = np.asarray(position, np.float64).astype(np.float32)
        same = (self.reuse.positions.astype(np.float32) == p).all(axis=1)
        if self.reuse.directions is not None and direction is not None:
            d = np.asarray(direction, np.float64)
            d = (d / np.linalg.norm(d)).astype(np.float32)
            same &= (self.reuse.directions.astype(np.float32) == d).all(axis=1)
        hits = np.nonzero(same)[0]
        return int(hits[0]) if len(hits) else None

    def move_light(self, position, direction=None) -> LightUpdate:
        """Place the light at ``position`` (a spot: aimed along ``direction``):
        by reuse when it is a precomputed position, else by an ordinary run
        of the frame's photon count at that position."""
        self._check_open()
        t0 = time.perf_counter()
        try:
            position = tuple(float(c) for c in position)
        except (TypeError, ValueError):
            raise OclgiError(f"a light position is 3 numbers, got {position!r}") from None
        if len(position) != 3 or not np.isfinite(position).all():
            raise OclgiError(f"a light position is 3 finite numbers, got {position!r}")
        frame = self.frame_of(position, direction)
        if frame is not None:
            self.result = self.reuse.estimate(frame, self.estimator, self.reweighting)
            self.device_irradiance = self.result.device_irradiance
            done = LightUpdate(reused=True, frame=frame)
        else:
            done = LightUpdate(reused=False, frame=None, paths_traced=self.reuse.paths_per_position)
            self._recompute(position, direction)
        self.frame, self.position, self.direction = frame, position, direction
        done.seconds = {"total": time.perf_counter() - t0}
        return done

    def _recompute(self, position, direction):
        from ..scene_parameters import light_name

        key = light_name(self.engine.scene, self.reuse.light)
        changes = {f"{key}.position": position}
        if direction is not None:
            changes[f"{key}.direction"] = tuple(float(c) for c in direction)
        view = self.engine.posed()  # the session's engine keeps the animation's light for the reuse store
        view._apply_parameters(changes)
        p = self.params
        self.result = view.irradiance(self.points.copy(), method=p.method, photons=p.photons, radius=p.radius,
                                      seed=p.seed, max_depth=p.max_depth, extension=p.extension,
                                      count_emitted=p.count_emitted, **self.options)
        irr = np.zeros((len(self.points), 4), np.float32)
        irr[:, :3] = self.result.irradiance
        self.device_irradiance = cl.Buffer(self.engine.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                           hostbuf=irr)

    def _set_estimator(self, est) -> None:
        """The estimator of every frame; disc indexing re-weights the tails'
        stored pairs (oclgi/tracing/light_reweight.py: the same sums, the
        tails not walked again each frame). With final gathering the sums
        are the gather hits' discs (``FinalGather.inner``): the hits depend
        on the geometry alone, which a light session never moves, and the
        direct light at the points and the hits is taken at each frame's
        resolve with the light where the frame has it."""
        from ..tracing.light_reweight import Reweighting

        self.estimator = est
        sums = est.summing
        self.reweighting = Reweighting(self.reuse, sums) if sums.name == "detp_disc_index" else None

    def move(self, name: str, matrix):
        raise OclgiError("objects do not move in a light session (its stored paths are the light animation's); "
                         "move objects in an oclgi.Session")

    # -- reading ------------------------------------------------------------------------
    def irradiance(self) -> np.ndarray:
        self._check_open()
        return self.result.irradiance

    def accumulators(self) -> np.ndarray:
        self._check_open()
        return self.result.accumulators

    def render(self, exposure: float = 1.0):
        self._check_camera(self.camera is not None, "render")
        return self.engine.shade(self.points, self.device_irradiance, exposure)

    # -- changing what is estimated ----------------------------------------------------------
    def set_estimator(self, method: str | None = None, radius: float | None = None, **options) -> float:
        """Another estimator from now on; the light's current position estimated again."""
        self._check_open()
        t0 = time.perf_counter()
        est = self.reuse.estimator(self.points, method or self.params.method,
                                   self.params.radius if radius is None else radius, **options)
        self._set_estimator(est)
        self.params, self.options = self.reuse.run_params, dict(options)
        self.move_light(self.position, self.direction)
        return time.perf_counter() - t0

    def set_camera(self, camera) -> float:
        """View through ``camera`` (camera sessions only); the light's current position estimated again."""
        self._check_camera(self.camera is not None, "set_camera")
        t0 = time.perf_counter()
        self.points = self._points(None, camera)
        self._set_estimator(self.reuse.estimator(self.points, self.params.method, self.params.radius,
                                                 **self.options))
        self.move_light(self.position, self.direction)
        return time.perf_counter() - t0
