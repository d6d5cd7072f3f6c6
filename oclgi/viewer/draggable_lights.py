"""The lights a page can drag: the scene's point and spot lights, by name.

Each has the key its position has among the session's parameters
(``light.NAME.position``, oclgi/scene_parameters.py), its index among the point
and spot lights (what ``LightSession`` takes) and its ``path``, the
precomputed positions of the scene file's light animation (None without
one): at those a light session reuses the stored paths instead of
tracing (oclgi/incremental/light_session.py).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DraggableLight:
    key: str  # the parameters' name of the light ("light.NAME" or "light.#i")
    index: int  # among the scene's point and spot lights (LightSession's ``light``)
    kind: str  # "point" or "spot"
    position: tuple  # as loaded
    path: list | None  # the animation's positions (rows of 3), or None


def movable_lights(scene) -> dict:
    """name -> DraggableLight for the scene's point and spot lights, named
    as the parameters name them (without ``light.``)."""
    from ..scene_parameters import light_name
    from ..scene.lights import PointLight, SpotLight, all_lights

    out = {}
    lights = [x for x in all_lights(scene) if isinstance(x, (PointLight, SpotLight))]
    for index, light in enumerate(lights):
        key = light_name(scene, light)
        path = None if light.path is None else [[float(c) for c in row[:3]] for row in light.path]
        out[key[len("light."):]] = DraggableLight(key, index, "spot" if isinstance(light, SpotLight) else "point",
                                                  tuple(float(c) for c in light.position), path)
    return out
