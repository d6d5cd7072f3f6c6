"""What every session offers (ARCHITECTURE move M5), whatever its estimator.

A session is a scene at a pose of its own, an estimator and query points
(fixed sensors or a camera's visible points), with every photon path kept
on the device so that changes cost only what depends on them:

- ``move(name, matrix)``: an object moves; the paths it touches are
  re-traced (the update, DESIGN.md section 4);
- ``irradiance()``, ``render(exposure)``: the current estimate;
- ``set_camera(camera)``: another view; only the camera points are traced;
- ``set_estimator(method, **options)``: another estimator or its options;
  the stored paths are summed again, nothing is re-traced;
- ``close()``: the session's device memory is freed now.

``Session`` (DETP variants and Impact Count: exact sums, equal to a
recomputation bit for bit) and ``PhotonMapSession`` (k-nearest estimates:
the thesis' practical update, or an exact one) implement it;
``open_session`` (oclgi/incremental/open_session.py) picks the one a method
needs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import OclgiError


@dataclass
class UpdateStats:
    paths: int  # paths re-traced
    segments_removed: int  # old suffix segments taken away (n_Rec)
    segments_added: int  # new suffix segments added
    points: int = 0  # points recomputed (camera sessions' dynamic points; Photon Maps' searched points)
    rays_changed: int = 0  # final gathering: the gather rays whose hit the move changed (FinalGather.regather)
    seconds: dict = field(default_factory=dict)


@runtime_checkable
class IncrementalSession(Protocol):
    """The methods every session has (module doc)."""

    def move(self, name: str, matrix) -> UpdateStats: ...

    def irradiance(self) -> np.ndarray: ...

    def render(self, exposure: float = 1.0): ...

    def set_camera(self, camera) -> float: ...

    def set_estimator(self, method: str | None = None, **options) -> float: ...

    def close(self) -> None: ...


class SessionBase:
    """Closing, shared by the sessions: ``close()`` frees every device buffer
    the session owns (its store, estimators, view and pose; the engine's
    are shared and stay), after which every method refuses; also a context
    manager (``with oclgi.Session(...) as s:``)."""

    closed = False

    def close(self) -> None:
        if self.closed:
            return
        from ..cl.release import release

        self.queue.finish()
        pose = self.engine.compiled.pose
        self.released_buffers = release(*vars(self).values()) | pose.release()
        self.closed = True
        for k in [k for k in vars(self) if k not in ("queue", "params", "closed", "released_buffers")]:
            setattr(self, k, None)

    def parameters(self):
        """What can change in this session (materials, lights, its camera,
        its photons and estimator), by name; set values, then ``update()``:
        only what depends on them is recomputed (oclgi/scene_parameters.py)."""
        from ..scene_parameters import Parameters

        self._check_open()
        return Parameters(self)

    def _parameter_values(self) -> dict:
        from ..scene_parameters import values

        self._check_open()
        view = getattr(self, "view", None)
        return values(self.engine.scene, self.params, None if view is None else view.cam)

    def _new_tables(self, changes: dict):
        """The session's engine view with the changed materials and lights
        (checked, nothing changed yet on a refusal): (scene, compiled, run changes)."""
        from ..scene_parameters import changed_scene, kinds

        scene, run = changed_scene(self.engine.scene, changes)
        compiled = self.engine.compiled.with_scene(scene) if "tables" in kinds(changes) else None
        return scene, compiled, run

    def _renew_store(self, scene, compiled, what: set, new, done) -> None:
        """An update's new scene and tables (``compiled``, None: unchanged)
        on the session's engine view, and its store for the run parameters
        ``new``: traced anew when the tables, seed or depth changed, resized
        when only the photon count did (the kept paths copied), else kept;
        ``done`` (an Updated) counts the paths traced and dropped."""
        from .segment_store import SegmentStore

        p = self.params
        self.engine.scene = scene
        if compiled is not None:
            self.engine.compiled = compiled
        old = self.store
        if compiled is not None or "trace" in what:
            self.store = SegmentStore(self.engine, new.photons, new.seed, new.max_depth)
            done.paths_traced = new.photons
        elif "photons" in what:
            self.store, _ = old.resized(new.photons)
            done.paths_traced = max(new.photons - p.photons, 0)
            done.paths_dropped = max(p.photons - new.photons, 0)
        if self.store is not old:
            self._release_store(old)
            self.scale = self.store.scale
        self.params = new

    def _release_store(self, old) -> None:
        """Free a store the session has replaced (resized, re-traced): the
        estimators forget what they kept of it (DetpDiscIndex's crossing
        lists), and only the buffers nothing of the session still holds are
        released (a resized store keeps some of the old one's)."""
        from ..cl.release import release

        for est in (getattr(self, "estimator", None), getattr(self, "dyn_est", None)):
            if est is not None:
                est.forget_store(old)
        release(old, keep=(self,))

    def _place(self, name: str, matrix) -> tuple[int, float]:
        """A move's start: object ``name`` placed at ``matrix``; (its id, when the move began)."""
        self._check_open()
        obj = self.engine.scene.object_id(name)
        t0 = time.perf_counter()
        self.engine.place(name, matrix)
        return obj, t0

    def _check_open(self) -> None:
        if self.closed:
            raise OclgiError(f"this {type(self).__name__} is closed")

    def _check_camera(self, is_camera: bool, method: str) -> None:
        """Open, and a camera session, as ``method`` (render, set_camera) needs."""
        self._check_open()
        if not is_camera:
            raise OclgiError(f"{method}() needs a camera session (points=None)"
                             + ("; this one has fixed points" if method == "set_camera" else ""))

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
