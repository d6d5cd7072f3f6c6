"""Hostile pages, generated: random messages to the viewer's socket (wrong
types, NaN and infinities, huge sizes, unknown kinds, deep nesting, valid
requests among them), then a legitimate move. After every case the server
answers, and the page's colours equal the API's at the session's state
(its poses, lights, estimator and photons, as it reports them) bit for bit.
A deterministic slice runs in ``make test``, a longer one in the full suite."""

import json
import math

import numpy as np
import pytest
from viewer_client import PageModel, connect, open_viewer, reference_colours, run_pages, sync

PHOTONS = 4_000
GARBAGE = [None, True, "x", "", [], {}, [1, 2], {"a": 1}, -1, 0, 1e308, -1e308, 2**70, "NaN", 1.5, 3]


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    return open_viewer(scenes_dir / "cornell_bunny.toml", photons=PHOTONS, edge=0.5)


def _pose(rng):
    a = rng.uniform(0, 2 * math.pi)
    c, s = math.cos(a), math.sin(a)
    return [c, 0, s, rng.uniform(-0.4, 0.4), 0, 1, 0, 0, -s, 0, c, rng.uniform(-0.4, 0.4), 0, 0, 0, 1]


def _message(rng, viewer) -> str:
    """One message: a valid request (small, so the case stays quick), a
    valid one with a field replaced by garbage, or no request at all."""
    light = next(iter(viewer.lights), None)
    valid = [
        {"type": "move", "object": "bunny", "matrix": _pose(rng)},
        {"type": "photons", "count": int(rng.integers(1_000, 8_000))},
        {"type": "estimator", "radius": float(rng.uniform(0.03, 0.2))},
        {"type": "estimator", "method": str(rng.choice(["detp_disc_index", "detp", "photon_map"]))},
        {"type": "sync", "id": int(rng.integers(0, 1000))},
        {"type": "ack", "seq": int(rng.integers(0, 5))},
        {"type": "render", "id": 1, "width": 8, "height": 8,
         "camera": {"position": [0, 1, 3.9], "look_at": [0, 1, 0], "fov": 39.3}},
        {"type": "level", "level": int(rng.integers(0, len(viewer.levels) + 1))},
        {"type": "bake", "id": 2},
    ]
    if light is not None:
        valid.append({"type": "light", "light": light, "position": [float(x) for x in rng.uniform(-0.5, 0.5, 3)]})
    msg = dict(valid[int(rng.integers(len(valid)))])
    roll = rng.random()
    if roll < 0.6:  # a field (or the type) replaced by garbage
        key = str(rng.choice(list(msg)))
        msg[key] = GARBAGE[int(rng.integers(len(GARBAGE)))]
    elif roll < 0.7:
        msg = {"type": str(rng.choice(["nope", "MOVE", "", "render "]))}
    elif roll < 0.75:
        return "[" * 5000 + "]" * 5000
    elif roll < 0.8:
        msg["count" if "count" in msg else "width"] = 10**9  # huge sizes
    text = json.dumps(msg, allow_nan=True)
    if roll >= 0.95:  # NaN and infinities as JSON's readers take them
        text = text.replace("1.5", "NaN").replace("3", "Infinity")
    return text


class FuzzedPage(PageModel):
    """A page that also asked for renders and bakes: their images (OGVR) and glTF files (OGVB) are not
    colour frames."""

    def apply(self, data: bytes) -> None:
        if data[:4] not in (b"OGVR", b"OGVB"):
            super().apply(data)


async def _case(client, viewer, rng, n_messages):
    ws, page, _ = await connect(client, viewer, FuzzedPage)
    for _ in range(n_messages):
        await ws.send_str(_message(rng, viewer))
    state = await sync(ws, page, 10_001)  # the server answers, after everything it was sent
    if state["method"] == "photon_map":  # its practical update tends to recomputation, not equal to it:
        await ws.send_str(json.dumps({"type": "estimator", "method": "detp_disc_index"}))  # a DETP session now
    await ws.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": _pose(rng)}))
    await ws.send_str(json.dumps({"type": "level", "level": 0}))  # the tessellation's colours, whatever was drawn
    state = await sync(ws, page, 10_002)
    run = {"method": state["method"], "photons": state["photons"]}
    if state["method"] == "photon_map":
        run["k"] = state["k"]
    else:
        run["radius"] = state["radius"]
    lights = {f"{viewer.lights[name].key}.position": tuple(p) for name, p in state["lights"].items()
              if list(p) != list(viewer.lights[name].position)}
    if lights:
        run["lights"] = lights
    expected = reference_colours(viewer, state["poses"], **run)
    assert page.shows(expected), state
    for k, level in enumerate(viewer.levels, 1):  # each level: the averaging of the exact colours
        await ws.send_str(json.dumps({"type": "level", "level": k}))
        await sync(ws, page, 10_002 + k)
        assert page.shows_level(k, level.colours(expected)), k
    await ws.close()


def _fuzz(viewer, seed, cases, n_messages):
    rng = np.random.default_rng(seed)

    async def test(client):
        for _ in range(cases):
            await _case(client, viewer, rng, n_messages)

    run_pages(viewer, test)


def test_generated_messages_leave_the_session_exact(viewer):
    _fuzz(viewer, seed=0, cases=3, n_messages=20)


@pytest.mark.full
def test_generated_messages_campaign(viewer):
    _fuzz(viewer, seed=1, cases=25, n_messages=40)
