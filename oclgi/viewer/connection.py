"""One page (one WebSocket) and its session: requests in, updates and colour frames out.

Each socket owns one session over the shared engine and tessellation
(oclgi/incremental/open_session.py), opened when the socket opens and
closed (its device memory freed) when it closes. The page must never wait
on the server, and the server must never fall behind a drag:

- requests wait in a queue that one task works through, one device call
  at a time (the device calls of every socket share one worker thread:
  kernels are shared objects whose arguments are set per call);
- a move of the object the last queued request already moves replaces it:
  while an update runs, the drag's newer poses overwrite each other and
  only the latest is computed;
- a colour frame is the difference from the last frame sent
  (oclgi/viewer/vertex_colours.py), so a frame can be skipped: while newer
  moves wait and the page has not yet applied two frames, the frame of a
  pose already overtaken is not sent; the last one always is;
- the frames are of the mesh the page says it draws (a ``level`` message):
  the tessellation, or while the view moves a level of detail
  (oclgi/viewer/level_of_detail.py) whose colours the server averages from
  the exact ones, so a drag sends the level's colours only and the
  tessellation's follow, as one difference, when the page asks for them
  again;
- a light drag updates by a light session (oclgi/incremental/light_session.py)
  while every object is where it was loaded and the light has precomputed
  positions (its ``path``): reused there, recomputed elsewhere; otherwise
  the session re-traces with the light moved (a parameter update). The
  session catches up on the light when it is next needed (a move, an
  estimator, photons);
- an estimator of the other family (Photon Maps against DETP and Impact
  Count) opens a session of the other kind at the current poses and
  lights, and closes the old one;
- a bake is the tessellation at the session's poses with the colours the
  page is shown, as a glTF file (oclgi/bake.py's layout, radiance);
- a render is the engine's image at the session's poses and lights from
  the page's camera, batch by batch with progress messages between; a
  large one in a process of its own (oclgi/viewer/render_process.py), so
  that it never holds other pages' moves;
- a flood (more than MAX_MESSAGES_PER_SECOND requests in a second) is
  refused, with one error a second, and the session is left as it was;
  a ``sync`` is still answered, so the page learns where things stand.
"""

from __future__ import annotations

import asyncio
import json
import struct
import time

import numpy as np

from ..errors import OclgiError
from ..io import png_bytes
from .messages import BadMessage, Request, parse
from .vertex_colours import FrameEncoder

MAX_MESSAGES_PER_SECOND = 240  # a drag sends one a display frame (60 to 144 a second)
MAX_IN_FLIGHT = 2  # frames sent and not yet acknowledged before an overtaken one is skipped
MAX_QUEUED = 64  # requests waiting (moves of one object coalesce, so only mixed ones pile up)
RENDER_MAGIC = b"OGVR"  # a render's binary message (Connection._send_render)
# Paths a render traces between other pages' work: its batches are separate
# calls on the device's thread, so a move of another page waits for one
# batch, not for the render (a large image's batch takes about a tenth of a
# second on 2 cores), and a page that goes away stops its render there.
RENDER_BATCH = 20_000
RENDER_HEADER = struct.Struct("<4sIIII")
BAKE_MAGIC = b"OGVB"  # a bake's binary message: magic, uint32 length, the GLB file
BAKE_HEADER = struct.Struct("<4sI")


class Connection:
    """A socket's session, its queue of requests and the frames it was sent."""

    def __init__(self, viewer, ws, number: int):
        self.viewer, self.ws, self.number = viewer, ws, number
        self.session = None
        self.pending: list[Request] = []
        self.wake = asyncio.Event()
        self.seq = 0  # updates applied (the colour frames carry the latest)
        self.in_flight = 0
        self.encoders = [FrameEncoder(len(viewer.tess.vertices))] + [
            FrameEncoder(len(lv.positions), k) for k, lv in enumerate(viewer.levels, 1)]
        self.level = 0  # the mesh the page draws: 0 the tessellation, k its k-th level of detail
        self.colours = None  # the current solution's colours (not necessarily sent yet)
        self.updates = 0  # moves of objects and lights computed
        self.coalesced = 0  # moves replaced by a newer one (of the same object or light) before they ran
        self.window_start, self.window_count, self.window_warned = time.monotonic(), 0, False
        self.segments = 0
        self.renders = 0
        self.task = None
        self.lights = {}  # parameter changes of the lights moved ("light.NAME.position" -> position)
        self.light_session = None  # (light name, LightSession), opened at the first drag of a light with a path
        self.current = None  # the session whose solution the page is shown: self.session or the light session's
        self.session_stale = False  # the lights moved in the light session only
        self.no_reuse = {}  # light name -> why a light session cannot serve it

    # -- device work (in the viewer's worker thread) ----------------------------------------
    def _colours(self) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        colours = self.viewer.colours(self.current.irradiance())
        return colours, time.perf_counter() - t0

    def _book(self, key, photons: int, what: str) -> None:
        """Hold a session of ``photons`` paths in the server's budget (oclgi/viewer/ledger.py)."""
        from .ledger import session_bytes

        v = self.viewer
        v.ledger.book(key, session_bytes(photons, v.run.max_depth, len(v.points)), what)

    def _open(self):
        v = self.viewer
        self._book(self, v.run.photons, f"a page's session of {v.run.photons:,} photons")
        try:
            self.session = self.current = v.open_session()
        except BaseException:
            v.ledger.release_page(self)
            raise
        self.segments = int(self.session.store.path_len().sum())
        return self._colours()

    def _main(self):
        """The session, brought up to the lights' positions if they moved in the light session only."""
        s = self.session
        if self.session_stale:
            params = s.parameters()
            for key, value in self.lights.items():
                params[key] = value
            params.update()
            self.segments = int(s.store.path_len().sum())
            self.session_stale = False
        self.current = s
        return s

    def _at_loaded_poses(self) -> bool:
        return all(np.array_equal(self.session.engine.pose_matrix(name), m.loaded)
                   for name, m in self.viewer.movable.items())

    def _light_session_for(self, name: str):
        """(the light session that places light ``name``, None) or (None, why none can): a light session
        opened for it at its first drag; one that refused it is not tried again (``no_reuse``)."""
        from ..incremental.light_session import LightSession

        light = self.viewer.lights[name]
        others = {k for k in self.lights if not k.startswith(light.key + ".")}
        p = self.session.params
        if light.path is None:
            reason = "the light has no precomputed positions (a path in the scene file)"
        elif p.method == "photon_map":
            reason = "a Photon Map session recomputes"
        elif not self._at_loaded_poses():
            reason = "an object moved: the stored light paths are the scene's as loaded"
        elif others:
            reason = "another light moved"
        else:
            reason = self.no_reuse.get(name)  # a light session refused this light before
        if reason:
            return None, reason
        if self.light_session is not None and self.light_session[0] == name:
            return self.light_session[1], None
        self._drop_light_session()
        self._book((self, "light"), p.photons, f"a light session of {p.photons:,} photons")
        try:
            ls = LightSession(self.viewer.engine, self.viewer.points, light=light.index, photons=p.photons,
                              seed=p.seed, max_depth=p.max_depth, method=p.method, radius=p.radius)
        except OclgiError as exc:  # another emitter, a glossy first hit: reuse does not apply
            self.viewer.ledger.release((self, "light"))
            self.no_reuse[name] = str(exc)
            return None, str(exc)
        self.light_session = (name, ls)
        return ls, None

    def _drop_light_session(self) -> None:
        if self.light_session is not None:
            self.light_session[1].close()
            self.light_session = None
        self.viewer.ledger.release((self, "light"))

    def _move_light(self, name: str, position: tuple) -> dict:
        light = self.viewer.lights[name]
        key = f"{light.key}.position"
        ls, why = self._light_session_for(name)
        if ls is not None:
            done = ls.move_light(position)
            self.lights[key] = position
            self.session_stale, self.current = True, ls
            return {"light": name, "by": "light session", "reused": done.reused, "frame": done.frame,
                    "paths_traced": done.paths_traced, "seconds": dict(done.seconds)}
        s = self._main()
        params = s.parameters()
        params[key] = position
        up = params.update()
        self.lights[key] = position
        self.segments = int(s.store.path_len().sum())
        return {"light": name, "by": "session", "reused": False, "frame": None, "why": why,
                "paths_traced": up.paths_traced, "seconds": {"total": up.seconds}}

    def _switch_family(self, fields: dict) -> dict:
        """A session of the other kind (Photon Maps <-> DETP, Impact Count) at the current poses and lights."""
        t0 = time.perf_counter()
        old = self._main()
        method = fields["method"]
        options = {}
        if method == "photon_map":
            if "radius" in fields:
                raise BadMessage("estimator: the Photon Map has no disc radius (it takes k)")
            if "k" in fields:
                options["k"] = fields["k"]
        else:
            if "k" in fields:
                raise BadMessage(f"estimator: k is the Photon Map's option, not {method}'s")
            if "radius" in fields:
                options["radius"] = fields["radius"]
        self._book((self, "switch"), old.params.photons, f"a {method} session of {old.params.photons:,} photons "
                   "beside the page's own while it switches")
        try:
            new = self.viewer.open_session(method, old.params.photons, self.lights, **options)
        except BaseException:
            self.viewer.ledger.release((self, "switch"))
            raise
        self.viewer.sessions_opened += 1
        try:
            for name, m in self.viewer.movable.items():
                pose = old.engine.pose_matrix(name)
                if not np.array_equal(pose, m.loaded):
                    new.move(name, pose)
        except BaseException:
            self._close_session(new)
            self.viewer.ledger.release((self, "switch"))
            raise
        self._drop_light_session()
        self.session = self.current = new
        self._close_session(old)
        self.viewer.ledger.release((self, "switch"))  # the page holds one session again, the same size
        self.segments = int(new.store.path_len().sum())
        return {"switched": True, "seconds": {"total": time.perf_counter() - t0}}

    def _render_plan(self, fields: dict, args: dict):
        """The engine's image from the page's camera at the session's poses
        and lights (``Engine.render``'s steps) with the run arguments
        ``args`` (render_process.render_args), booked in the server's
        budget: (the engine at those poses and lights, camera)."""
        from ..scene.scene import Camera

        engine = self.session.engine.posed()
        if self.session_stale:
            engine._apply_parameters(self.lights)
        cam = Camera(position=fields["position"], look_at=fields["look_at"], up=fields["up"], fov=fields["fov"],
                     width=fields["width"], height=fields["height"])
        need = engine.render_need(cam, args.get("spp", 1), args)
        self.viewer.ledger.book((self, "render"), need.device_total + need.host,
                                f"a {cam.width}x{cam.height} render")
        return engine, cam

    def _render_run(self, fields: dict, args: dict):
        """(engine, run) of the render in this process, its batches of RENDER_BATCH paths left to step."""
        engine, cam = self._render_plan(fields, args)
        run = engine.render_run(cam, **args)
        run.set_batch(min(run.batch, RENDER_BATCH))
        return engine, run

    def _render_job(self, fields: dict, args: dict) -> dict:
        """The render as a job for a process of its own (oclgi/viewer/render_process.py)."""
        from .render_process import job_of

        engine, cam = self._render_plan(fields, args)
        poses = {name: engine.pose_matrix(name) for name in self.viewer.movable}
        return job_of(engine, poses, self.lights, cam, args, RENDER_BATCH)

    def _apply(self, req: Request) -> dict:
        info = {"kind": req.kind}
        if req.kind == "light":
            info.update(self._move_light(req.fields["light"], req.fields["position"]))
            colours, read = self._colours()
            info["seconds"]["read"] = read
            return {"info": info, "colours": colours}
        s = self._main()
        if req.kind == "estimator" and "method" in req.fields and (
                (req.fields["method"] == "photon_map") != (s.params.method == "photon_map")):
            info.update(self._switch_family(req.fields))
            s = self.session
        elif req.kind == "move":
            st = s.move(req.fields["object"], req.fields["matrix"])
            self.segments += st.segments_added - st.segments_removed
            info.update(paths=st.paths, segments_removed=st.segments_removed, segments_added=st.segments_added,
                        points=st.points, seconds=dict(st.seconds))
        elif req.kind == "estimator":
            self._drop_light_session()  # its estimator is the old one
            t0 = time.perf_counter()
            f = dict(req.fields)
            if "k" in f:
                if s.params.method != "photon_map":
                    raise BadMessage("estimator: k is the Photon Map's option; this session estimates with "
                                     f"{s.params.method}")
                s.set_estimator("photon_map", k=f.pop("k"))
            if f:
                if "radius" in f and s.params.method == "photon_map":
                    raise BadMessage("estimator: the Photon Map has no disc radius (it takes k)")
                params = s.parameters()
                for key, value in f.items():
                    params[key] = value
                params.update()
            info["seconds"] = {"total": time.perf_counter() - t0}
        elif req.kind == "photons":
            count = req.fields["count"]
            self._book(self, max(count, s.params.photons), f"a session of {count:,} photons")  # refused: as it was
            self._drop_light_session()
            try:
                info["seconds"] = {"total": s.set_photons(count)}
            finally:  # what the session holds now: the new count, or the old one if it failed
                self._book(self, s.params.photons, f"a session of {s.params.photons:,} photons")
            self.segments = int(s.store.path_len().sum())
        colours, read = self._colours()
        info["seconds"]["read"] = read
        return {"info": info, "colours": colours}

    # -- the socket's side ----------------------------------------------------------------
    def describe(self) -> dict:
        s = self.session
        p = s.params
        return {"photons": int(p.photons), "segments": int(self.segments), "method": p.method,
                "radius": None if p.method == "photon_map" else float(p.radius),
                "k": s.options.get("k") if p.method == "photon_map" else None,
                "methods": list(self.viewer.methods),
                "poses": {name: s.engine.pose_matrix(name).reshape(-1).tolist() for name in self.viewer.movable},
                "lights": {name: list(self.lights.get(f"{light.key}.position", light.position))
                           for name, light in self.viewer.lights.items()},
                "shown_by": "light session" if self.current is not self.session else "session"}

    async def send_json(self, msg: dict) -> None:
        if not self.ws.closed:
            await self.ws.send_str(json.dumps(msg))

    async def error(self, text: str, request: str | None = None) -> None:
        await self.send_json({"type": "error", "message": text, "request": request})

    async def open(self) -> None:
        self.colours, read = await self.viewer.device(self._open)
        self.viewer.sessions_opened += 1
        await self.send_json({"type": "hello", "connection": self.number, "seconds": {"read": read},
                              "setup_seconds": self.session.setup_seconds, **self.describe()})
        await self.send_frame()
        self.task = asyncio.create_task(self._work())

    def receive(self, text) -> str | None:
        """Take one message from the page; the error to send back, if refused."""
        now = time.monotonic()
        if now - self.window_start >= 1.0:
            self.window_start, self.window_count, self.window_warned = now, 0, False
        try:
            v = self.viewer
            req = parse(text, v.movable, v.methods, v.diagonal, tuple(v.lights), v.box, len(v.levels))
        except BadMessage as exc:
            return str(exc)
        if req.kind == "ack":
            if self.in_flight > 0:
                self.in_flight -= 1
            return None
        self.window_count += req.kind != "sync"  # a sync is answered even in a flood (queued, it is bounded)
        if req.kind != "sync" and self.window_count > MAX_MESSAGES_PER_SECOND:
            if self.window_warned:
                return ""  # refused, already said this second
            self.window_warned = True
            return (f"too many requests: at most {MAX_MESSAGES_PER_SECOND} a second; the rest of this second's "
                    "are dropped")
        if req.kind == "level":  # no device work: the next frame (now, or after the update running) is of it
            self.level = req.fields["level"]
            self.wake.set()
            return None
        last = self.pending[-1] if self.pending else None
        if (req.kind in ("move", "light") and last is not None and last.kind == req.kind
                and last.fields.get("object") == req.fields.get("object")
                and last.fields.get("light") == req.fields.get("light")):
            self.pending[-1] = req
            self.coalesced += 1
        elif len(self.pending) >= MAX_QUEUED:
            return f"too many requests waiting (at most {MAX_QUEUED}); this one is dropped"
        else:
            self.pending.append(req)
        self.wake.set()
        return None

    async def send_frame(self, force: bool = True) -> bool:
        """Send the colours the page lacks (unless an overtaken frame may be skipped)."""
        if not force and self.in_flight >= MAX_IN_FLIGHT:
            return False
        level = self.level
        colours = self.colours if level == 0 else self.viewer.levels[level - 1].colours(self.colours)
        frame = self.encoders[level].frame(colours, self.seq)
        if frame is not None and not self.ws.closed:
            self.in_flight += 1
            await self.ws.send_bytes(frame)
        return True

    async def _work(self) -> None:
        while True:
            await self.wake.wait()
            self.wake.clear()
            while self.pending:
                req = self.pending.pop(0)
                if req.kind == "sync":
                    await self.send_frame()
                    await self.send_json({"type": "synced", "id": req.fields["id"], "seq": self.seq,
                                          "updates": self.updates, "coalesced": self.coalesced, **self.describe()})
                    continue
                if req.kind == "render":
                    await self._send_render(req)
                    continue
                if req.kind == "bake":
                    await self._send_bake(req)
                    continue
                t0 = time.perf_counter()
                try:
                    done = await self.viewer.device(self._apply, req)
                except OclgiError as exc:
                    await self.error(str(exc), req.kind)
                    continue
                self.seq += 1
                self.updates += req.kind in ("move", "light")
                self.colours = done["colours"]
                info = done["info"]
                info["seconds"]["server"] = time.perf_counter() - t0
                await self.send_json({"type": "update", "seq": self.seq, **info, **self.describe()})
                newer_move = any(r.kind in ("move", "light") for r in self.pending)
                await self.send_frame(force=not newer_move)
            await self.send_frame()

    async def _send_render(self, req: Request) -> None:
        """Render, with a ``render_progress`` message a batch (at most ten a
        second) and one before the last step, then ``rendered`` and the image (RENDER_MAGIC: uint32 id
        index, width, height, PNG length; the PNG; float32 radiance[H][W][3]).
        A render past IN_PROCESS_PIXELS (IN_PROCESS_GATHERED with the default estimate) runs in a process of its own."""
        from .render_process import elsewhere, render_args

        ident, t0 = req.fields["id"], time.perf_counter()
        await self.send_json({"type": "render_started", "id": ident, "width": req.fields["width"],
                              "height": req.fields["height"]})
        f = req.fields
        args = render_args(self.session.params, self.session.options, f["width"], f["height"], f["plain"])
        try:
            image = await (self._render_elsewhere if elsewhere(f["width"], f["height"], args)
                           else self._render_here)(req, args)
        except OclgiError as exc:
            await self.error(str(exc), "render")
            return
        finally:
            self.viewer.ledger.release((self, "render"))
        if image is None:
            return  # the page went away: its render stopped
        radiance, pixels = image
        p = self.session.params
        done = {"seconds": time.perf_counter() - t0, "method": p.method, "photons": int(p.photons)}
        png = await asyncio.get_running_loop().run_in_executor(None, png_bytes, pixels)  # seconds at 4096^2
        h, w = radiance.shape[:2]
        self.renders += 1
        await self.send_json({"type": "rendered", "id": ident, "index": self.renders, "width": w, "height": h,
                              "seconds": done["seconds"], "method": done["method"], "photons": done["photons"]})
        if not self.ws.closed:
            await self.ws.send_bytes(RENDER_HEADER.pack(RENDER_MAGIC, self.renders, w, h, len(png)) + png
                                     + np.ascontiguousarray(radiance, "<f4").tobytes())

    def _bake(self, exposure: float) -> bytes:
        """The GLB of the tessellation at the session's poses, coloured by the current solution's radiance."""
        from ..bake import baked_scene, glb_bytes
        from ..incremental.attached_points import AttachedPoints

        v = self.viewer
        placed = AttachedPoints(self.session.engine, v.tess.points(), as_loaded=True)  # as oclgi bake places them
        placed.update()
        p = placed.points
        return glb_bytes(baked_scene(v.engine.scene, v.tess, p.positions[:, :3], p.normals[:, :3], self.colours,
                                     "radiance", exposure))

    async def _send_bake(self, req: Request) -> None:
        t0 = time.perf_counter()
        glb = await self.viewer.device(self._bake, req.fields["exposure"])
        await self.send_json({"type": "baked", "id": req.fields["id"], "bytes": len(glb), "seq": self.seq,
                              "seconds": time.perf_counter() - t0})
        if not self.ws.closed:
            await self.ws.send_bytes(BAKE_HEADER.pack(BAKE_MAGIC, len(glb)) + glb)

    async def _progress(self, ident, traced: int, paths: int, stage: str = "photons") -> None:
        """``stage``: "photons" while they are traced, "final" once for the last step (the exact direct
        light and the gather of the default estimate: seconds for a large image, with nothing to count)."""
        await self.send_json({"type": "render_progress", "id": ident, "traced": traced, "paths": paths,
                              "stage": stage})

    async def _render_here(self, req: Request, args: dict):
        """(radiance, pixels) rendered on the device's thread a batch a call, or None if the page went away."""
        ident, last = req.fields["id"], 0.0
        engine, run = await self.viewer.device(self._render_run, req.fields, args)
        while not run.done:  # a batch a call: other pages' requests run in between
            if self.ws.closed:
                return None  # the page went away: its render stops here
            await self.viewer.device(run.step)  # the first also has the estimator check the run
            now = time.monotonic()
            if now - last >= 0.1 or run.done:
                last = now
                await self._progress(ident, int(run.traced), int(run.paths.count))
        await self._progress(ident, int(run.traced), int(run.paths.count), "final")
        image = await self.viewer.device(lambda: engine.render_result(run, run.finish()))
        return image.radiance, image.pixels

    async def _render_elsewhere(self, req: Request, args: dict):
        """(radiance, pixels) rendered by a process of its own, or None if
        the page went away (the process is then killed, as when the page's
        task is cancelled)."""
        from .render_process import RenderProcess

        job = await self.viewer.device(self._render_job, req.fields, args)
        worker = RenderProcess(job)
        try:
            while True:
                msg = await worker.receive(lambda: not self.ws.closed)
                if msg is None:
                    if self.ws.closed:
                        return None
                    raise OclgiError("the render's process ended without an image (killed, or out of memory?)")
                if msg[0] == "progress":
                    await self._progress(req.fields["id"], *msg[1:])
                elif msg[0] == "error":
                    raise OclgiError(msg[1])
                else:
                    return msg[1], msg[2]
        finally:
            worker.stop()

    def close(self):
        """Stop the work and close the session (now, in the device's thread,
        even when the socket's handler is cancelled on the way out); a
        future of that."""
        if self.task is not None:
            self.task.cancel()
        session, self.session = self.session, None
        return asyncio.wrap_future(self.viewer.executor.submit(self._close_session, session))

    def _close_session(self, session) -> None:
        if session is None:
            return
        if self.session is None:  # the page is closing: all it held
            self.viewer.ledger.release_page(self)
        if self.light_session is not None and session is not self.light_session[1]:
            self._drop_light_session()
        session.close()
        self.viewer.sessions_closed += 1
        self.viewer.buffers_released += len(session.released_buffers)
