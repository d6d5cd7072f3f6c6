"""A glTF file's punctual lights (KHR_lights_punctual) as oclgi lights, and
its camera (``read_camera``).

trimesh reads a glTF's meshes but not this extension, so the file's JSON is
read here once more, for its lights and the nodes that place them:

===========  ===============================================================
glTF         oclgi (oclgi/scene/lights.py)
===========  ===============================================================
point        PointLight: ``intensity`` candela of ``color``
spot         SpotLight: ``intensity`` candela on the axis, cone_angle =
             outerConeAngle (default pi/4), cone_delta = outer - inner
             (innerConeAngle, default 0). glTF's suggested falloff is a
             squared linear ramp in cos theta; oclgi's is pbrt's smoothstep
             over the same band.
directional  SunLight: ``intensity`` lux of ``color``
===========  ===============================================================

A light shines along its node's -Z axis, placed by the node's world
transform (``matrix``, or translation x rotation x scale, parent by
parent). ``range`` (a cut-off distance for real-time engines) is ignored:
physical lights have none. Colours are linear RGB, scaled so that their
luminance is the given candela or lux (oclgi/photometry.py).
"""

from __future__ import annotations

import json
import math
import struct

import numpy as np

from ..errors import OclgiError
from .lights import PointLight, SpotLight, SunLight

EXTENSION = "KHR_lights_punctual"


def document(data: bytes, suffix: str):
    """The glTF JSON of a .gltf (text) or .glb (its first chunk), or None."""
    try:
        if suffix == ".glb":
            if len(data) < 20 or data[:4] != b"glTF":
                return None
            length, kind = struct.unpack_from("<II", data, 12)
            if kind != 0x4E4F534A:  # "JSON"
                return None
            data = data[20:20 + length]
        doc = json.loads(data.decode("utf-8"))
    except (ValueError, UnicodeDecodeError, struct.error, RecursionError):
        return None  # trimesh has read the file: a glTF it reads but this cannot has no lights for us
    return doc if isinstance(doc, dict) else None


def _quat_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _numbers(value, n, where):
    a = np.asarray(value, dtype=object)
    if a.shape != (n,) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in a):
        raise OclgiError(f"{where}: expected {n} numbers, got {value!r}")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise OclgiError(f"{where}: expected {n} finite numbers, got {value!r}")
    return a


def _local(node: dict, where: str) -> np.ndarray:
    if "matrix" in node:
        return _numbers(node["matrix"], 16, where + ".matrix").reshape(4, 4).T  # column-major
    m = np.eye(4)
    if "scale" in node:
        m = np.diag([*_numbers(node["scale"], 3, where + ".scale"), 1.0])
    if "rotation" in node:
        r = np.eye(4)
        q = _numbers(node["rotation"], 4, where + ".rotation")
        if not np.linalg.norm(q) > 0:
            raise OclgiError(f"{where}.rotation: a zero quaternion")
        r[:3, :3] = _quat_matrix(q / np.linalg.norm(q))
        m = r @ m
    if "translation" in node:
        t = np.eye(4)
        t[:3, 3] = _numbers(node["translation"], 3, where + ".translation")
        m = t @ m
    return m


def walk(doc: dict, label: str):
    """(index, node, world matrix) of every node of the default scene, depth
    first in the file's order (glTF's node graph, checked as it is read)."""
    nodes = doc.get("nodes") or []
    if not isinstance(nodes, list):
        raise OclgiError(f"{label}: malformed nodes")
    scenes = doc.get("scenes") or [{"nodes": list(range(len(nodes)))}]
    scene = doc.get("scene", 0)
    if not isinstance(scene, int) or not 0 <= scene < len(scenes) or not isinstance(scenes[scene], dict):
        raise OclgiError(f"{label}: scene {scene!r} is not one of the file's scenes")
    roots = scenes[scene].get("nodes", [])
    if not isinstance(roots, list):
        raise OclgiError(f"{label}: scene {scene}: malformed nodes")
    stack = [(i, np.eye(4)) for i in reversed(roots)]
    seen = set()
    while stack:
        i, parent = stack.pop()
        if not isinstance(i, int) or not 0 <= i < len(nodes) or not isinstance(nodes[i], dict):
            raise OclgiError(f"{label}: node {i!r} is not one of the file's nodes")
        if i in seen:  # a node reached twice: a cycle, which glTF forbids
            raise OclgiError(f"{label}: node {i} is its own ancestor")
        seen.add(i)
        node, where = nodes[i], f"{label}: node {i}"
        world = parent @ _local(node, where)
        yield i, node, world
        children = node.get("children", [])
        if not isinstance(children, list):
            raise OclgiError(f"{where}.children: expected a list of node indices, got {children!r}")
        stack.extend((c, world) for c in reversed(children))


def read(data: bytes, suffix: str, label: str) -> list:
    """The punctual lights of a glTF file's default scene, in its world space."""
    doc = document(data, suffix)
    if doc is None:
        return []
    table = (doc.get("extensions") or {}).get(EXTENSION) if isinstance(doc.get("extensions"), dict) else None
    if not isinstance(table, dict) or not table.get("lights"):
        return []
    defs = table["lights"]
    if not isinstance(defs, list):
        raise OclgiError(f"{label}: {EXTENSION}: malformed lights")
    out = []
    for i, node, world in walk(doc, label):
        ext = (node.get("extensions") or {}).get(EXTENSION) if isinstance(node.get("extensions"), dict) else None
        if isinstance(ext, dict) and "light" in ext:
            k = ext["light"]
            if not isinstance(k, int) or not 0 <= k < len(defs):
                raise OclgiError(f"{label}: node {i}: {EXTENSION} light {k!r} is not one of the file's {len(defs)}")
            light = _light(defs[k], world, f"{label}: {EXTENSION} light {k}")
            if light is not None:
                out.append(light)
    return out


def read_camera(data: bytes, suffix: str, label: str, height: int = 256):
    """The first perspective camera of a glTF file's default scene as an
    oclgi Camera (looking along its node's -Z, +Y up; ``yfov`` the vertical
    field of view; the image ``height`` pixels high and as wide as its
    ``aspectRatio`` says, square without one), or None."""
    doc = document(data, suffix)
    cameras = doc.get("cameras") if doc is not None else None
    if not isinstance(cameras, list) or not cameras:
        return None
    for i, node, world in walk(doc, label):
        k = node.get("camera")
        if not isinstance(k, int) or not 0 <= k < len(cameras) or not isinstance(cameras[k], dict):
            continue
        persp = cameras[k].get("perspective")
        if cameras[k].get("type") != "perspective" or not isinstance(persp, dict):
            continue
        yfov = persp.get("yfov")
        aspect = persp.get("aspectRatio", 1.0)
        if not (isinstance(yfov, (int, float)) and 0 < yfov < math.pi and isinstance(aspect, (int, float))
                and 0.01 < aspect < 100):
            raise OclgiError(f"{label}: camera {k}: yfov must be in (0, pi) and aspectRatio positive")
        cam = camera_at(world, math.degrees(yfov), aspect, height)
        if cam is None:
            raise OclgiError(f"{label}: camera {k}'s node {i} has a degenerate transform")
        return cam
    return None


def camera_at(world: np.ndarray, fov: float, aspect: float, height: int):
    """A camera at a node's world transform, looking along its -Z with +Y up
    (glTF's and trimesh's convention): ``fov`` vertical, in degrees, the
    image ``height`` pixels high and ``aspect`` times as wide; None for a
    degenerate transform."""
    from .scene import Camera

    world = np.asarray(world, np.float64)
    eye, forward, up = world[:3, 3], -world[:3, 2], world[:3, 1]
    if not (np.isfinite(world).all() and np.linalg.norm(forward) > 0 and np.linalg.norm(up) > 0):
        return None
    return Camera(position=tuple(float(x) for x in eye), look_at=tuple(float(x) for x in eye + forward),
                  up=tuple(float(x) for x in up / np.linalg.norm(up)), fov=float(fov),
                  width=max(1, int(round(height * aspect))), height=height)


def _light(d, world: np.ndarray, where: str):
    from ..photometry import intensity_from_candela, irradiance_from_lux

    if not isinstance(d, dict):
        raise OclgiError(f"{where}: expected an object, got {d!r}")
    kind = d.get("type")
    colour = _numbers(d.get("color", [1.0, 1.0, 1.0]), 3, where + ".color")
    value = d.get("intensity", 1.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise OclgiError(f"{where}.intensity: expected a number >= 0, got {value!r}")
    if value == 0 or not colour.max() > 0 or (colour < 0).any():
        return None  # dark: nothing to trace (a negative colour is no light either)
    position = tuple(float(x) for x in world[:3, 3])
    direction = -world[:3, 2]
    if not np.linalg.norm(direction) > 0:
        raise OclgiError(f"{where}: its node's transform has no -Z axis (scale 0)")
    direction = tuple(float(x) for x in direction / np.linalg.norm(direction))
    if kind == "point":
        return PointLight(position, intensity_from_candela(value, colour))
    if kind == "spot":
        spot = d.get("spot") or {}
        outer = spot.get("outerConeAngle", math.pi / 4)
        inner = spot.get("innerConeAngle", 0.0)
        for key, v in (("outerConeAngle", outer), ("innerConeAngle", inner)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise OclgiError(f"{where}.spot.{key}: expected a number, got {v!r}")
        if not 0 <= inner < outer <= math.pi / 2:
            raise OclgiError(f"{where}.spot: expected 0 <= innerConeAngle < outerConeAngle <= pi/2, "
                             f"got {inner!r} and {outer!r}")
        return SpotLight(position, direction, intensity_from_candela(value, colour),
                         cone_angle=math.degrees(outer), cone_delta=math.degrees(outer - inner))
    if kind == "directional":
        return SunLight(direction, irradiance_from_lux(value, colour))
    raise OclgiError(f"{where}.type: expected 'point', 'spot' or 'directional', got {kind!r}")


def transformed(light, m: np.ndarray, shift: np.ndarray):
    """``light`` placed by a scene file's mesh transform (p -> m p + shift)."""
    from dataclasses import replace

    def point(p):
        return tuple(float(x) for x in np.asarray(m) @ np.asarray(p, np.float64) + shift)

    def direction(d):
        v = np.asarray(m) @ np.asarray(d, np.float64)
        return tuple(float(x) for x in v / np.linalg.norm(v))

    if isinstance(light, SunLight):
        return replace(light, direction=direction(light.direction))
    if isinstance(light, SpotLight):
        return replace(light, position=point(light.position), direction=direction(light.direction))
    return replace(light, position=point(light.position))
