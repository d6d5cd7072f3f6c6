"""What a camera ray that leaves the scene sees: the scene's sky or
environment map (oclgi/scene/lights.py), as the device's ``Background``
record and its texels (``kernels/background.h``); black without either. A
scene with a sky has no transparent pixels: the sky is part of its image."""

from __future__ import annotations

import numpy as np

from ..cl.constants import EMITTER_ENVMAP, EMITTER_SKY
from ..cl.layout import Background
from .lights import EnvMapLight, SkyLight


def record(scene) -> tuple[np.ndarray, np.ndarray]:
    """(the Background record (1,), float4 texels (>= 1 row))."""
    bg = np.zeros(1, Background)
    bg["kind"] = -1
    texels = np.zeros((1, 4), np.float32)
    for light in getattr(scene, "lights", []):
        if isinstance(light, SkyLight):
            bg["kind"], bg["radiance"] = EMITTER_SKY, light.radiance
            bg["up"], bg["hemisphere"] = np.asarray(light.up) / np.linalg.norm(light.up), int(light.hemisphere)
            break
        if isinstance(light, EnvMapLight):
            rad = np.asarray(light.radiance, np.float32)
            h, w = rad.shape[:2]
            bg["kind"], bg["width"], bg["height"] = EMITTER_ENVMAP, w, h
            texels = np.zeros((h * w, 4), np.float32)
            texels[:, :3] = rad.reshape(-1, 3)
            break
    return bg, texels


def visible(scene) -> bool:
    """Whether the scene's background has radiance (a sky or a map)."""
    return any(isinstance(x, (SkyLight, EnvMapLight)) for x in getattr(scene, "lights", []))
