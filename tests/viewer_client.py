"""The page's side of the viewer's socket, in Python (tests/test_viewer_*.py):
the colour frames decoded independently of oclgi/viewer/vertex_colours.py,
and the reference a page must equal: a fresh session at the same pose."""

from __future__ import annotations

import asyncio
import json
import math
import struct

import numpy as np


PHOTONS = 20_000  # the tests' runs: small, the bunny still casting a shadow
EDGE = 0.3


def open_viewer(scene_path, photons: int = PHOTONS, edge: float = EDGE):
    """The server's shared part (engine, tessellation, run) over a scene file."""
    import oclgi
    from oclgi.scene.tessellate import tessellate
    from oclgi.viewer.server import Viewer

    scene = oclgi.load_file(scene_path)
    return Viewer(oclgi.Engine(scene), tessellate(scene, edge), photons=photons)


def page_headers(viewer) -> dict:
    """What the page's requests carry: the server's token (oclgi/viewer/guard.py)."""
    return {"Authorization": f"token {viewer.guard.token}"}


def run_pages(viewer, test) -> None:
    """``await test(client)`` against the viewer's application, every request carrying the token."""
    from aiohttp.test_utils import TestClient, TestServer  # aiohttp: setup.cfg's test extra

    async def main():
        async with TestClient(TestServer(viewer.app()), headers=page_headers(viewer)) as client:
            await test(client)
    asyncio.run(main())


async def connect(client, viewer, page_type=None):
    """A page's socket: (ws, page, its hello, or the error that refused it);
    the first frame (every colour) applied."""
    ws = await client.ws_connect("/socket")
    page = (page_type or PageModel)(len(viewer.tess.vertices), [len(lv.positions) for lv in viewer.levels])
    hello = await receive_until(ws, page, lambda m: m["type"] in ("hello", "error"))
    if hello["type"] == "hello":
        page.apply(await ws.receive_bytes(timeout=120))
    return ws, page, hello


def as_shown(colours: np.ndarray, e: int) -> np.ndarray:
    """The float16 bits a page holds for float32 ``colours`` at scale 2^e:
    colours * 2^-e rounded to the nearest float16 (ties to even)."""
    return np.ldexp(np.asarray(colours, np.float32), -e).astype(np.float16).view(np.uint16)


class PageModel:
    """What a page holds: float16 colours at a power-of-two scale, applied
    frame by frame; of the tessellation (``half``, ``e``) and of each level
    of detail (``levels[k - 1]``: [half, e, seq])."""

    def __init__(self, n_vertices: int, level_sizes=()):
        self.half = np.zeros((n_vertices, 3), np.uint16)
        self.e = 0
        self.levels = [[np.zeros((n, 3), np.uint16), 0, -1] for n in level_sizes]
        self.seq, self.frames, self.messages, self.sizes, self.frame_levels = -1, 0, [], [], []

    @property
    def colours(self) -> np.ndarray:
        """The colours shown, float32 (exact: a float16 times a power of two)."""
        return np.ldexp(self.half.view(np.float16).astype(np.float32), self.e)

    def shows(self, colours: np.ndarray) -> bool:
        """The page holds ``colours`` (float32, the API's) rounded to float16 at its scale, bit for bit."""
        return np.array_equal(self.half, as_shown(colours, self.e))

    def shows_level(self, k: int, colours: np.ndarray) -> bool:
        """Level k's halves are ``colours`` (float32) rounded to float16 at its scale, bit for bit."""
        half, e, _ = self.levels[k - 1]
        return np.array_equal(half, as_shown(colours, e))

    def apply(self, data: bytes) -> None:
        magic, seq, mode, e, level = struct.unpack_from("<4sIIiI", data)
        assert magic == b"OGVC"
        half = self.half if level == 0 else self.levels[level - 1][0]
        n = len(half)
        if mode == 0:
            (count,) = struct.unpack_from("<I", data, 20)
            assert count == n and len(data) == 24 + 6 * n
            half[:] = np.frombuffer(data, "<u2", offset=24).reshape(-1, 3)
        else:
            assert mode == 1
            r, s = struct.unpack_from("<II", data, 20)
            start = np.frombuffer(data, "<u4", r, offset=28)
            length = np.frombuffer(data, "<u4", r, offset=28 + 4 * r)
            single = np.frombuffer(data, "<u4", s, offset=28 + 8 * r)
            values = np.frombuffer(data, "<u2", offset=28 + 8 * r + 4 * s).reshape(-1, 3)
            assert len(values) == int(length.sum()) + s and (length >= 2).all()
            at = 0
            for a, k in zip(start.tolist(), length.tolist()):  # one obvious copy per run
                half[a:a + k] = values[at:at + k]
                at += k
            for i, v in zip(single.tolist(), range(at, at + s)):
                half[i] = values[v]
        if level == 0:
            self.e = e
        else:
            self.levels[level - 1][1:] = [e, seq]
        self.seq, self.frames = seq, self.frames + 1
        self.sizes.append(len(data))
        self.frame_levels.append(level)


async def receive_until(ws, page: PageModel, predicate, ack: bool = True):
    """Apply frames and collect messages until ``predicate(msg)``; that message."""
    while True:
        msg = await ws.receive(timeout=120)
        if msg.type.name == "BINARY":
            page.apply(msg.data)
            if ack:
                await ws.send_str(json.dumps({"type": "ack", "seq": page.seq}))
            continue
        assert msg.type.name == "TEXT", msg
        data = json.loads(msg.data)
        page.messages.append(data)
        if predicate(data):
            return data


async def sync(ws, page: PageModel, ident: int = 1) -> dict:
    await ws.send_str(json.dumps({"type": "sync", "id": ident}))
    return await receive_until(ws, page, lambda m: m["type"] == "synced" and m["id"] == ident)


def expected_radiance(scene, tess, irradiance) -> np.ndarray:
    """rho / pi * E + Le per vertex, float64, from the vertex's source material."""
    mats = [scene.materials[m] for m in np.asarray(scene.tri_material)[tess.vertex_tri]]
    rho = np.array([m.diffuse_albedo for m in mats], np.float64)
    le = np.array([m.emission for m in mats], np.float64)
    return le + rho * np.asarray(irradiance, np.float64) / math.pi


def reference_colours(viewer, poses: dict, **run) -> np.ndarray:
    """The colours the API gives at ``poses`` (name -> row-major 16): a new
    session over the viewer's points (opened where the tessellation was
    made, so its points on movable objects start where the mesh has them),
    each object moved there once; the viewer's run parameters unless
    ``run`` overrides them (``lights``: parameter changes, the lights moved
    before the session opens)."""
    from oclgi.incremental.open_session import open_session

    r = viewer.run
    args = dict(method=r.method, photons=r.photons, radius=r.radius)
    args.update(run)
    if args["method"] == "photon_map":
        args.pop("radius")
    lights = args.pop("lights", None)
    with open_session(viewer.lit_engine(lights), viewer.points, **args) as s:
        for name, m in poses.items():
            if not np.array_equal(np.reshape(m, (4, 4)), viewer.movable[name].loaded):
                s.move(name, np.array(m, np.float64).reshape(4, 4))
        return viewer.colours(s.irradiance())
