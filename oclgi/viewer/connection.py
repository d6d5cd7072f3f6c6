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
- a flood (more than MAX_MESSAGES_PER_SECOND requests in a second) is
  refused, with one error a second, and the session is left as it was;
  a ``sync`` is still answered, so the page learns where things stand.
"""

from __future__ import annotations

import asyncio
import json
import time

import numpy as np

from ..errors import OclgiError
from .messages import BadMessage, Request, parse
from .vertex_colours import FrameEncoder

MAX_MESSAGES_PER_SECOND = 240  # a drag sends one a display frame (60 to 144 a second)
MAX_IN_FLIGHT = 2  # frames sent and not yet acknowledged before an overtaken one is skipped
MAX_QUEUED = 64  # requests waiting (moves of one object coalesce, so only mixed ones pile up)


class Connection:
    """A socket's session, its queue of requests and the frames it was sent."""

    def __init__(self, viewer, ws, number: int):
        self.viewer, self.ws, self.number = viewer, ws, number
        self.session = None
        self.pending: list[Request] = []
        self.wake = asyncio.Event()
        self.seq = 0  # updates applied (the colour frames carry the latest)
        self.in_flight = 0
        self.encoder = FrameEncoder(len(viewer.tess.vertices))
        self.colours = None  # the current solution's colours (not necessarily sent yet)
        self.updates = 0  # moves computed
        self.coalesced = 0  # moves replaced by a newer one before they ran
        self.window_start, self.window_count, self.window_warned = time.monotonic(), 0, False
        self.segments = 0
        self.task = None

    # -- device work (in the viewer's worker thread) ----------------------------------------
    def _colours(self) -> tuple[np.ndarray, float]:
        t0 = time.perf_counter()
        colours = self.viewer.colours(self.session.irradiance())
        return colours, time.perf_counter() - t0

    def _open(self):
        v = self.viewer
        self.session = v.open_session()
        self.segments = int(self.session.store.path_len().sum())
        return self._colours()

    def _apply(self, req: Request) -> dict:
        s = self.session
        info = {"kind": req.kind}
        if req.kind == "move":
            st = s.move(req.fields["object"], req.fields["matrix"])
            self.segments += st.segments_added - st.segments_removed
            info.update(paths=st.paths, segments_removed=st.segments_removed, segments_added=st.segments_added,
                        points=st.points, seconds=dict(st.seconds))
        elif req.kind == "estimator":
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
            info["seconds"] = {"total": s.set_photons(req.fields["count"])}
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
                "methods": list(self.viewer.methods_for(s)),
                "poses": {name: s.engine.pose_matrix(name).reshape(-1).tolist() for name in self.viewer.movable}}

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
            req = parse(text, self.viewer.movable, self.viewer.methods_for(self.session), self.viewer.diagonal)
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
        last = self.pending[-1] if self.pending else None
        if (req.kind == "move" and last is not None and last.kind == "move"
                and last.fields["object"] == req.fields["object"]):
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
        frame = self.encoder.frame(self.colours, self.seq)
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
                t0 = time.perf_counter()
                try:
                    done = await self.viewer.device(self._apply, req)
                except OclgiError as exc:
                    await self.error(str(exc), req.kind)
                    continue
                self.seq += 1
                self.updates += req.kind == "move"
                self.colours = done["colours"]
                info = done["info"]
                info["seconds"]["server"] = time.perf_counter() - t0
                await self.send_json({"type": "update", "seq": self.seq, **info, **self.describe()})
                newer_move = any(r.kind == "move" for r in self.pending)
                await self.send_frame(force=not newer_move)
            await self.send_frame()

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
        session.close()
        self.viewer.sessions_closed += 1
        self.viewer.buffers_released += len(session.released_buffers)
