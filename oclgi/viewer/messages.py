"""The viewer's socket protocol: what a page may ask, checked before anything runs.

Every message from the page is a JSON object with a ``type``:

==============  =====================================================  ==================
``type``        fields                                                 what it does
==============  =====================================================  ==================
``move``        ``object`` (a movable object's name), ``matrix``       places the object
                (16 numbers, row-major world-from-object)
``estimator``   ``method`` and/or ``radius`` (DETP disc radius),       re-sums the paths
                ``k`` (Photon Maps' neighbours)
``photons``     ``count``                                              traces or drops the
                                                                       difference
``ack``         ``seq`` (the colour frame the page has applied)        lets the next one go
``sync``        ``id`` (any number)                                    answered ``synced``
                                                                       once all before it
                                                                       is done and sent
``light``       ``light`` (a point or spot light's name),              places the light
                ``position`` (3 numbers)
``render``      ``id`` (any number), ``camera`` (``position``,         answered by the
                ``look_at``, ``up``, ``fov`` in degrees, vertical),    image: progress,
                ``width``, ``height`` (pixels), ``plain``              then ``rendered``
                (optional, true: the photons' estimate alone, not
                ``oclgi render``'s default)
``level``       ``level`` (0: the tessellation, k >= 1: its k-th       the colour frames
                level of detail, oclgi/viewer/level_of_detail.py)      are of that mesh
``bake``        ``id`` (any number), ``exposure`` (optional, > 0)      answered by a glTF
                                                                       of the current pose
==============  =====================================================  ==================

A move must keep the object rigid: its matrix is the object's loaded
transform composed with a rotation and a translation (scaling or shearing
it would change its surface, which the page's mesh and the stored paths'
object are not). Anything else (not JSON, too long, a field of the wrong
type, a number out of range, NaN) is refused with one line, sent back as an
``error`` message; the session is not touched.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from ..errors import OclgiError

MAX_MESSAGE_BYTES = 16_384  # a move is about 400 bytes; anything longer is refused unread
MAX_PHOTONS = 4_000_000  # per tab: photons x max_depth x 48 bytes stay on the device
MAX_K = 1000  # Photon Maps' neighbours
MAX_RENDER_SIDE = 4096  # pixels: a render's camera points and image stay well inside the device's memory
MAX_EXPOSURE = 2.0 ** 20  # a bake's scale on the radiance (the page's +-8 EV and far beyond)
RIGID_TOLERANCE = 1e-4  # of the rotation's columns: orthonormal to float32-ish rounding of a page's matrix


class BadMessage(OclgiError):
    """A refused message: its text goes back to the page."""


@dataclass(frozen=True)
class Request:
    kind: str  # "move", "estimator", "photons", "ack", "sync", "light", "render", "level", "bake"
    fields: dict


def _number(msg: dict, key: str, kind: str):
    v = msg.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise BadMessage(f"{kind}: {key!r} must be a finite number, got {v!r}")
    return v


def _integer(msg: dict, key: str, kind: str, lo: int, hi: int) -> int:
    v = _number(msg, key, kind)
    if v != int(v) or not lo <= v <= hi:
        raise BadMessage(f"{kind}: {key!r} must be a whole number from {lo:,} to {hi:,}, got {v!r}")
    return int(v)


@dataclass(frozen=True)
class Movable:
    """What a move of one object is checked against."""

    loaded: np.ndarray  # its world-from-object matrix when the tessellation was made
    centre: np.ndarray  # the centre of its box then
    lo: np.ndarray  # where its centre may go: the scene's box grown by its diagonal
    hi: np.ndarray


def rigid_matrix(values, obj: Movable, name: str) -> np.ndarray:
    """The 4x4 matrix of 16 row-major numbers, checked to be the object's
    loaded transform moved rigidly, and to keep it near the scene."""
    if not isinstance(values, list) or len(values) != 16 or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise BadMessage(f"move: 'matrix' must be a list of 16 numbers (row-major 4x4), got {_short(values)}")
    m = np.array(values, np.float64).reshape(4, 4)
    if not np.isfinite(m).all():
        raise BadMessage(f"move: the matrix of {name!r} has a NaN or infinite entry")
    if not np.allclose(m[3], [0, 0, 0, 1], atol=0, rtol=0):
        raise BadMessage(f"move: the matrix of {name!r} is not affine (its last row must be 0 0 0 1)")
    rel = m @ np.linalg.inv(obj.loaded)
    r = rel[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=RIGID_TOLERANCE) or np.linalg.det(r) <= 0:
        raise BadMessage(f"move: the matrix of {name!r} is not a rotation and translation of the object as "
                         "loaded (it scales, shears or mirrors it)")
    c = r @ obj.centre + rel[:3, 3]
    if not ((c >= obj.lo).all() and (c <= obj.hi).all()):
        raise BadMessage(f"move: the matrix takes {name!r} to {np.round(c, 3).tolist()}, beyond the scene's box "
                         "grown by its diagonal")
    return m


def _short(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def _point(msg: dict, key: str, kind: str, lo=None, hi=None) -> tuple:
    v = msg.get(key)
    if not isinstance(v, list) or len(v) != 3 or not all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v):
        raise BadMessage(f"{kind}: {key!r} must be 3 finite numbers, got {_short(v)}")
    if lo is not None and not all(a <= c <= b for a, c, b in zip(lo, v, hi)):
        raise BadMessage(f"{kind}: {key!r} {_short(v)} is beyond the scene's box grown by its diagonal")
    return tuple(float(c) for c in v)


def _camera(msg: dict, lo, hi) -> dict:
    cam = msg.get("camera")
    if not isinstance(cam, dict):
        raise BadMessage(f"render: 'camera' must be an object with position, look_at, up and fov, got {_short(cam)}")
    out = {"position": _point(cam, "position", "render camera", lo, hi),
           "look_at": _point(cam, "look_at", "render camera"),
           "up": _point(cam, "up", "render camera") if "up" in cam else (0.0, 1.0, 0.0)}
    fov = _number(cam, "fov", "render camera")
    if not 0 < fov < 180:
        raise BadMessage(f"render camera: 'fov' must be in (0, 180) degrees, got {fov!r}")
    forward = np.subtract(out["look_at"], out["position"])
    if not np.linalg.norm(forward) > 0:
        raise BadMessage("render camera: 'look_at' must differ from 'position'")
    if np.linalg.norm(np.cross(forward / np.linalg.norm(forward), out["up"])) < 1e-6 * np.linalg.norm(out["up"]):
        raise BadMessage("render camera: 'up' must not be along the view direction (nor zero)")
    out["fov"] = float(fov)
    out["width"] = _integer(msg, "width", "render", 1, MAX_RENDER_SIDE)
    out["height"] = _integer(msg, "height", "render", 1, MAX_RENDER_SIDE)
    return out


def parse(text, movable: dict, methods: tuple, diagonal: float, lights: tuple = (), box=None,
          levels: int = 0) -> Request:
    """The request in ``text`` (a str from the socket), or BadMessage.
    ``movable``: name -> Movable; ``methods``: the
    estimators this session can switch to; ``diagonal``: the scene's (the
    largest disc radius); ``lights``: the point and spot lights' names;
    ``box``: (lo, hi), where a light or a render's camera may be (the
    scene's box grown by its diagonal); ``levels``: the levels of detail
    the page may draw besides the tessellation."""
    if not isinstance(text, str):
        raise BadMessage("messages must be JSON text, not binary")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE_BYTES:
        raise BadMessage(f"message too long ({len(text):,} characters; at most {MAX_MESSAGE_BYTES:,} bytes)")
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):
        raise BadMessage("message is not valid JSON") from None
    if not isinstance(msg, dict) or not isinstance(msg.get("type"), str):
        raise BadMessage('a message must be a JSON object with a "type"')
    kind = msg["type"]
    if kind == "move":
        name = msg.get("object")
        if not isinstance(name, str) or name not in movable:
            raise BadMessage(f"move: no movable object {_short(name)}; the movable ones are "
                             f"{', '.join(map(repr, movable)) or 'none'}")
        return Request("move", {"object": name, "matrix": rigid_matrix(msg.get("matrix"), movable[name], name)})
    if kind == "estimator":
        out = {}
        if "method" in msg:
            if msg["method"] not in methods:
                raise BadMessage(f"estimator: method must be one of {', '.join(methods)}, got {_short(msg['method'])}")
            out["method"] = msg["method"]
        if "radius" in msg:
            r = _number(msg, "radius", kind)
            if not 0 < r <= diagonal:
                raise BadMessage(f"estimator: radius must be in (0, {diagonal:.4g}] (the scene's diagonal), got {r!r}")
            out["radius"] = float(r)
        if "k" in msg:
            out["k"] = _integer(msg, "k", kind, 2, MAX_K)
        if not out:
            raise BadMessage("estimator: give method, radius or k")
        return Request("estimator", out)
    if kind == "photons":
        return Request("photons", {"count": _integer(msg, "count", kind, 1, MAX_PHOTONS)})
    if kind == "ack":
        return Request("ack", {"seq": _integer(msg, "seq", kind, 0, 2**32 - 1)})
    if kind == "sync":
        return Request("sync", {"id": _number(msg, "id", kind)})
    if kind == "level":
        return Request("level", {"level": _integer(msg, "level", kind, 0, levels)})
    if kind == "bake":
        exposure = _number(msg, "exposure", kind) if "exposure" in msg else 1.0
        if not 0 < exposure <= MAX_EXPOSURE:
            raise BadMessage(f"bake: 'exposure' must be in (0, {MAX_EXPOSURE:g}], got {exposure!r}")
        return Request("bake", {"id": _number(msg, "id", kind), "exposure": float(exposure)})
    lo, hi = box if box is not None else (None, None)
    if kind == "light":
        name = msg.get("light")
        if not isinstance(name, str) or name not in lights:
            raise BadMessage(f"light: no point or spot light {_short(name)}; the scene's are "
                             f"{', '.join(map(repr, lights)) or 'none'}")
        return Request("light", {"light": name, "position": _point(msg, "position", kind, lo, hi)})
    if kind == "render":
        plain = msg.get("plain", False)
        if not isinstance(plain, bool):
            raise BadMessage(f"render: 'plain' must be true or false, got {_short(plain)}")
        return Request("render", {"id": _number(msg, "id", kind), **_camera(msg, lo, hi), "plain": plain})
    raise BadMessage(f"unknown message type {_short(kind)} (move, estimator, photons, ack, sync, light, render, level, bake)")
