"""The page's side of the viewer's socket, in Python (tests/test_viewer_*.py):
the colour frames decoded independently of oclgi/viewer/vertex_colours.py,
and the reference a page must equal: a fresh session at the same pose."""

from __future__ import annotations

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


class PageModel:
    """What a page holds: the colours, applied frame by frame."""

    def __init__(self, n_vertices: int):
        self.colours = np.zeros((n_vertices, 3), np.float32)
        self.seq, self.frames, self.messages = -1, 0, []

    def apply(self, data: bytes) -> None:
        magic, seq, mode, count = struct.unpack_from("<4sIII", data)
        assert magic == b"OGVC"
        if mode == 0:
            assert count == len(self.colours) and len(data) == 16 + 12 * count
            self.colours[:] = np.frombuffer(data, "<f4", offset=16).reshape(-1, 3)
        else:
            assert mode == 1 and len(data) == 16 + 16 * count
            index = np.frombuffer(data, "<u4", count, offset=16)
            self.colours[index] = np.frombuffer(data, "<f4", offset=16 + 4 * count).reshape(-1, 3)
        self.seq, self.frames = seq, self.frames + 1


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
    ``run`` overrides them."""
    from oclgi.incremental.open_session import open_session

    r = viewer.run
    args = dict(method=r.method, photons=r.photons, radius=r.radius)
    args.update(run)
    with open_session(viewer.engine, viewer.points, **args) as s:
        for name, m in poses.items():
            if not np.array_equal(np.reshape(m, (4, 4)), viewer.movable[name].loaded):
                s.move(name, np.array(m, np.float64).reshape(4, 4))
        return viewer.colours(s.irradiance())
