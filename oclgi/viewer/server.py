"""``oclgi view``: the scene in the browser, its light kept exact as objects move.

An aiohttp server holds one engine and one tessellation of the scene
(oclgi/scene/tessellate.py), shared by every page; each page's WebSocket
gets a session of its own over the tessellation's vertices
(oclgi/viewer/connection.py). The page (oclgi/viewer/static/: plain
WebGL2, no build step, nothing fetched from elsewhere) draws the mesh
coloured by the vertices' radiance, so orbiting costs the server nothing;
a move sends the changed colours only.

Routes: ``/`` the page, ``/static/...`` its files, ``/mesh.bin`` the mesh
(oclgi/viewer/mesh_payload.py), ``/levels.bin`` its levels of detail
(oclgi/viewer/level_of_detail.py), ``/scene.json`` its description,
``/status.json`` the sessions open and closed and the device buffers the
closed ones released, ``/socket`` the WebSocket (oclgi/viewer/messages.py).

The server listens on 127.0.0.1 unless told otherwise: it runs whatever
the page asks on this machine's device, so binding another address is the
user's explicit choice. Every request passes oclgi/viewer/guard.py's
checks (a token, this server's Host names, the page's own Origin): other
web pages the user has open can neither drive it nor read the scene.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import json
import time
from pathlib import Path

import numpy as np

from ..errors import OclgiError
from .draggable_lights import movable_lights
from .guard import Guard
from .ledger import DEFAULT_MAX_PAGES, Ledger

STATIC = Path(__file__).resolve().parent / "static"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
MAX_FRAME_BYTES = 1 << 20  # longer than MAX_MESSAGE_BYTES, so a long message is answered, not cut off


class Viewer:
    """What every page shares: the engine, the tessellation, the device's
    worker thread; and the count of sessions for ``/status.json``."""

    def __init__(self, engine, tess, method=None, photons=None, radius=None, all_vertices: bool = False,
                 allow_origins=(), token: str | None = None, memory: int | None = None,
                 max_pages: int = DEFAULT_MAX_PAGES, levels=None):
        """``levels``: the levels of detail's face counts (None: level_of_detail's default, () none)."""
        from ..estimators import ESTIMATORS
        from .level_of_detail import levels_bytes, levels_of
        from .mesh_payload import description, mesh_bytes, vertex_objects
        from .messages import Movable
        from .object_points import object_points
        from .vertex_colours import vertex_terms

        self.engine, self.tess = engine, tess
        scene = engine.scene
        self.run = engine.run_params(method, photons, radius)  # checked now, not per tab
        if self.run.method != "photon_map" and not ESTIMATORS[self.run.method].incremental:
            raise OclgiError(f"method {self.run.method!r} has no incremental update; the viewer takes "
                             f"{', '.join(self.methods)}")
        self.terms = vertex_terms(scene, tess.vertex_tri)
        objects, movable = vertex_objects(scene, tess.vertex_tri)
        queried, self.value_of = object_points(tess, objects, np.asarray(scene.tri_material)[tess.vertex_tri],
                                               all_vertices)
        self.points = tess.points().subset(queried)  # each session's query points
        self.movable = {}  # name -> messages.Movable
        lo, hi = scene.bounds()
        for rank, obj in enumerate(movable):
            name = scene.objects[obj].name
            v = tess.vertices[objects == rank + 1]
            self.movable[name] = Movable(engine.pose_matrix(name), (v.min(axis=0) + v.max(axis=0)) / 2,
                                         lo - scene.diagonal, hi + scene.diagonal)
        self.lights = movable_lights(scene)
        self.box = (lo - scene.diagonal, hi + scene.diagonal)
        self.mesh = mesh_bytes(tess, objects)
        t0 = time.perf_counter()
        self.levels = levels_of(tess, objects, levels)
        self.levels_seconds = time.perf_counter() - t0
        self.levels_payload = levels_bytes(self.levels)
        self.description = dict(description(engine, tess, movable), points=len(self.points),
                                levels=[{"vertices": len(lv.positions), "faces": len(lv.faces), "cell": lv.cell}
                                        for lv in self.levels],
                                lights=[{"name": name, "kind": light.kind, "position": list(light.position),
                                         "path": light.path} for name, light in self.lights.items()])
        self.diagonal = scene.diagonal
        self.guard = Guard(DEFAULT_HOST, token, allow_origins)
        self.ledger = Ledger.for_device(engine.queue.device, memory, max_pages)  # every page's memory
        self.executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="oclgi-device")
        self.connections: set = set()
        self.sessions_opened = self.sessions_closed = self.buffers_released = 0
        self.numbered = 0

    def colours(self, irradiance) -> np.ndarray:
        """Every vertex's radiance from the irradiance at the query points."""
        from .vertex_colours import radiance

        return radiance(np.asarray(irradiance)[self.value_of], self.terms)

    @property
    def methods(self) -> tuple:
        """The estimators a page can switch to: the incremental ones by
        summing the stored paths again, Photon Maps (and back) by a session
        of the other kind (oclgi/viewer/connection.py)."""
        from ..estimators import ESTIMATORS

        return (*(m for m, c in ESTIMATORS.items() if c.incremental), "photon_map")

    def open_session(self, method=None, photons=None, lights: dict | None = None, **options):
        """A session at the loaded poses over the viewer's points: the
        viewer's run unless told otherwise; ``lights``: parameter changes
        (``light.NAME.position``) in force from the start."""
        from ..incremental.open_session import open_session

        r = self.run
        method = method or r.method
        if method != "photon_map":
            options.setdefault("radius", r.radius)
        return open_session(self.lit_engine(lights), self.points, method=method, photons=photons or r.photons,
                            **options)

    def lit_engine(self, lights: dict | None):
        """The shared engine, or a view of it with the lights moved."""
        if not lights:
            return self.engine
        view = self.engine.posed()
        view._apply_parameters(lights)
        return view

    async def device(self, fn, *args):
        """``fn(*args)`` in the device's worker thread (one call at a time)."""
        return await asyncio.get_running_loop().run_in_executor(self.executor, functools.partial(fn, *args))

    def status(self) -> dict:
        return {"open": len(self.connections),
                "opened": self.sessions_opened, "closed": self.sessions_closed,
                "buffers_released": self.buffers_released}

    # -- the application ----------------------------------------------------------
    def app(self):
        from aiohttp import web

        app = web.Application(middlewares=[self.guard.middleware()])
        app.router.add_get("/", self._page)
        app.router.add_get("/mesh.bin", functools.partial(self._binary, self.mesh))
        app.router.add_get("/levels.bin", functools.partial(self._binary, self.levels_payload))
        app.router.add_get("/scene.json", self._scene)
        app.router.add_get("/status.json", self._status)
        app.router.add_get("/socket", self._socket)
        app.router.add_static("/static/", STATIC)
        app.on_shutdown.append(self._shutdown)
        return app

    async def _page(self, request):
        from aiohttp import web

        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def _binary(self, body: bytes, request):
        from aiohttp import web

        return web.Response(body=body, content_type="application/octet-stream")

    async def _scene(self, request):
        from aiohttp import web

        return web.json_response(self.description)

    async def _status(self, request):
        from aiohttp import web

        return web.json_response(self.status())

    async def _socket(self, request):
        from aiohttp import WSMsgType, web

        from .connection import Connection

        ws = web.WebSocketResponse(max_msg_size=MAX_FRAME_BYTES)
        await ws.prepare(request)
        try:
            self.ledger.check_page(len(self.connections))
        except OclgiError as exc:  # one page too many: told, then closed
            await ws.send_str(json.dumps({"type": "error", "message": str(exc), "request": "open"}))
            await ws.close()
            return ws
        self.numbered += 1
        conn = Connection(self, ws, self.numbered)
        self.connections.add(conn)
        try:
            await conn.open()
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    refused = conn.receive(msg.data)
                elif msg.type == WSMsgType.BINARY:
                    refused = "messages must be JSON text, not binary"
                else:
                    break
                if refused:
                    await conn.error(refused)
        except OclgiError as exc:  # the session could not be opened (memory, say)
            if not ws.closed:
                await conn.error(str(exc), "open")
        finally:
            self.connections.discard(conn)
            await asyncio.shield(conn.close())
        return ws

    async def _shutdown(self, app):
        for conn in list(self.connections):
            await conn.ws.close(code=1001, message=b"server stopping")

    # -- serving ---------------------------------------------------------------
    async def serve(self, host: str, port: int, ready=None) -> None:
        """Serve until cancelled (Ctrl-C); ``ready(url)`` once listening, the
        URL with the page's token."""
        from aiohttp import web

        self.guard.listen_on(host)
        runner = web.AppRunner(self.app(), shutdown_timeout=5.0, access_log=None)
        await runner.setup()
        try:
            site = web.TCPSite(runner, host, port)
            try:
                await site.start()
            except OSError as exc:
                raise OclgiError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
            bound = runner.addresses[0][1] if port == 0 else port
            if ready is not None:
                ready(f"http://{'[' + host + ']' if ':' in host else host}:{bound}/?token={self.guard.token}")
            await asyncio.Event().wait()
        finally:
            await runner.cleanup()
            self.executor.shutdown(wait=True)
