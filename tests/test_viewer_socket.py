"""The viewer's socket (oclgi/viewer/): frames equal to a fresh session at
the same pose, bad input refused with the session intact and exact, moves
coalesced, sockets independent, a closed socket's session freed."""

import asyncio
import json
import math
import struct

import numpy as np
import pytest

from viewer_client import (PHOTONS, PageModel, connect, expected_radiance, open_viewer, receive_until,
                           reference_colours, run_pages, sync)


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    v = open_viewer(scenes_dir / "cornell_bunny.toml")
    yield v
    v.executor.shutdown(wait=True)


@pytest.fixture(scope="module")
def home(viewer):
    """The API's colours at the loaded pose."""
    return reference_colours(viewer, {})


def run(test, viewer):
    run_pages(viewer, test)


def bunny_at(dx, dz, angle=0.0):
    c, s = math.cos(angle), math.sin(angle)
    return [c, 0, s, dx, 0, 1, 0, 0, -s, 0, c, dz, 0, 0, 0, 1]


async def move(ws, matrix, name="bunny"):
    await ws.send_str(json.dumps({"type": "move", "object": name, "matrix": matrix}))


async def moves_exactly(ws, page, viewer, matrix, ident=1):
    """Move the bunny; the page's colours then equal the API's at the pose."""
    await move(ws, matrix)
    done = await sync(ws, page, ident)
    assert page.shows(reference_colours(viewer, done["poses"]))


def test_frames_equal_a_fresh_session_and_the_radiance_formula(viewer, home):
    async def test(client):
        ws, page, hello = await connect(client, viewer)
        assert hello["photons"] == PHOTONS and hello["method"] == "detp_disc_index"
        assert page.shows(home)
        e = _irradiance_of(viewer)[viewer.value_of]  # each vertex shows its query point's value
        # float16 at the frame's scale: half an ulp of 11 bits, or of the smallest subnormal
        np.testing.assert_allclose(page.colours, expected_radiance(viewer.engine.scene, viewer.tess, e),
                                   rtol=2.0 ** -11 + 2e-6, atol=2.0 ** (page.e - 25))
        assert page.colours.max() * 2.0 ** -page.e < 2 ** 12 <= 2 * page.colours.max() * 2.0 ** -page.e
        for m in (bunny_at(0.3, 0.0), bunny_at(0.6, -0.2, 0.5)):
            await move(ws, m)
            upd = await receive_until(ws, page, lambda m: m["type"] == "update")
            assert upd["paths"] > 0 and {"find", "retrace", "total", "read"} <= set(upd["seconds"])
        synced = await sync(ws, page)
        assert np.allclose(synced["poses"]["bunny"], bunny_at(0.6, -0.2, 0.5), atol=1e-6)  # float32 records
        ref = reference_colours(viewer, synced["poses"])
        assert page.shows(ref), "the page's colours are not a fresh session's at the pose"
        static = viewer.tess.vertex_tri < viewer.engine.scene.object_ranges()[0][1]
        changed = (ref != home).any(axis=1)
        assert changed[static].sum() > 20, "the floor's light did not follow the bunny"
        await ws.close()
    run(test, viewer)


def _irradiance_of(viewer):
    from oclgi.incremental.open_session import open_session

    engine = viewer.engine.posed()
    r = viewer.run
    with open_session(engine, viewer.points, method=r.method, photons=r.photons, radius=r.radius) as s:
        return s.irradiance()


BAD = [
    ({"type": "move", "object": "teapot", "matrix": bunny_at(0, 0)}, "no movable object"),
    ({"type": "move", "object": "bunny", "matrix": [float("nan")] + bunny_at(0, 0)[1:]}, "finite"),
    ({"type": "move", "object": "bunny", "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]}, "rotation"),
    ({"type": "move", "object": "bunny", "matrix": [1, 0.3, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}, "rotation"),
    ({"type": "move", "object": "bunny", "matrix": [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}, "mirror"),
    ({"type": "move", "object": "bunny", "matrix": bunny_at(0, 0)[:12]}, "16 numbers"),
    ({"type": "move", "object": "bunny", "matrix": bunny_at(3e9, 0)}, "beyond"),
    ({"type": "photons", "count": 0}, "whole number"),
    ({"type": "photons", "count": 10**12}, "whole number"),
    ({"type": "photons", "count": 1.5}, "whole number"),
    ({"type": "estimator", "radius": -0.1}, "radius"),
    ({"type": "estimator", "radius": 1e9}, "radius"),
    ({"type": "estimator", "radius": float("nan")}, "finite"),
    ({"type": "estimator", "method": "impact_count_x"}, "one of"),
    ({"type": "estimator", "method": "photon_map", "radius": 0.1}, "no disc radius"),
    ({"type": "estimator", "method": "detp", "k": 8}, "Photon Map"),
    ({"type": "light", "light": "lamp", "position": [0, 1, 0]}, "no point or spot light"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 0], "fov": 40},
      "width": 0, "height": 8}, "whole number"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 3], "fov": 40},
      "width": 8, "height": 8}, "differ"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 0], "fov": 180},
      "width": 8, "height": 8}, "fov"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1e9, 3], "look_at": [0, 1, 0], "fov": 40},
      "width": 8, "height": 8}, "beyond"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 0], "up": [0, 0, 1],
      "fov": 40}, "width": 8, "height": 8}, "along the view"),
    ({"type": "render", "id": 1, "camera": [0, 1, 3], "width": 8, "height": 8}, "camera"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 0], "fov": 40},
      "width": 8, "height": 8, "plain": "yes"}, "true or false"),
    ({"type": "render", "id": 1, "camera": {"position": [0, 1, 3], "look_at": [0, 1, 0], "fov": 40},
      "width": 10**6, "height": 8}, "whole number"),
    ({"type": "estimator", "k": 8}, "Photon Map"),
    ({"type": "estimator"}, "give"),
    ({"type": "level", "level": 99}, "whole number"),
    ({"type": "level", "level": -1}, "whole number"),
    ({"type": "level", "level": 0.5}, "whole number"),
    ({"type": "bake", "id": 1, "exposure": -1}, "exposure"),
    ({"type": "bake", "id": 1, "exposure": float("inf")}, "finite"),
    ({"type": "bake"}, "finite number"),
    ({"type": "teleport"}, "unknown message type"),
    ({"no": "type"}, "type"),
    ([1, 2, 3], "JSON object"),
]


def test_bad_input_is_refused_and_the_session_stays_exact(viewer):
    async def test(client):
        ws, page, _ = await connect(client, viewer)
        await move(ws, bunny_at(0.3, 0.1))
        before = await sync(ws, page)
        colours = page.colours.copy()
        texts = [json.dumps(m) for m, _ in BAD] + ["{not json", "x" * 100_000, json.dumps({"type": "sync"})]
        words = [w for _, w in BAD] + ["not valid JSON", "too long", "finite number"]
        for text, word in zip(texts, words):
            await ws.send_str(text)
            err = await receive_until(ws, page, lambda m: m["type"] in ("error", "update"))
            assert err["type"] == "error" and word in err["message"], (text[:80], err)
        await ws.send_bytes(b"\x00" * 64)
        err = await receive_until(ws, page, lambda m: m["type"] == "error")
        assert "binary" in err["message"]
        after = await sync(ws, page, 2)
        assert after["poses"] == before["poses"] and after["seq"] == before["seq"]
        assert after["photons"] == PHOTONS and after["radius"] == before["radius"]
        assert np.array_equal(page.colours, colours)
        await moves_exactly(ws, page, viewer, bunny_at(0.5, 0.2), 3)  # still exact, and still moving
        await ws.close()
    run(test, viewer)


def test_a_flood_of_moves_is_coalesced_refused_past_the_limit_and_ends_exact(viewer):
    from oclgi.viewer.connection import MAX_MESSAGES_PER_SECOND

    async def test(client):
        ws, page, _ = await connect(client, viewer)
        n = 3 * MAX_MESSAGES_PER_SECOND
        for i in range(n):
            await move(ws, bunny_at(0.5 * i / n, 0.0))
        done = await sync(ws, page)
        errors = [m for m in page.messages if m["type"] == "error"]
        assert len(errors) >= 1 and "too many requests" in errors[0]["message"]
        assert done["coalesced"] > 0 and done["updates"] < MAX_MESSAGES_PER_SECOND, done
        # the last move computed was one of the drag's, and the page equals a fresh session there
        assert any(np.allclose(done["poses"]["bunny"], bunny_at(0.5 * i / n, 0.0), atol=1e-6) for i in range(n))
        assert page.shows(reference_colours(viewer, done["poses"]))
        await ws.close()
    run(test, viewer)


def test_two_sockets_have_independent_sessions_and_a_closed_one_is_freed(viewer, home):
    async def test(client):
        for _ in range(400):  # the earlier tests' sockets closed: their sessions too (closed asynchronously)
            if not viewer.connections and viewer.sessions_closed == viewer.sessions_opened:
                break
            await asyncio.sleep(0.05)
        status0 = await (await client.get("/status.json")).json()
        assert status0["open"] == 0 and status0["closed"] == status0["opened"]
        a, page_a, _ = await connect(client, viewer)
        b, page_b, _ = await connect(client, viewer)
        assert (await (await client.get("/status.json")).json())["open"] == 2
        await move(a, bunny_at(0.6, 0.0))
        await sync(a, page_a)
        synced_b = await sync(b, page_b)
        assert synced_b["poses"]["bunny"] == bunny_at(0, 0) and page_b.shows(home)
        assert not page_a.shows(home)
        sessions = [c.session for c in viewer.connections]
        await b.close()
        for _ in range(200):
            status = await (await client.get("/status.json")).json()
            if status["closed"] > status0["closed"]:
                break
            await asyncio.sleep(0.05)
        assert status["open"] == 1 and status["closed"] == status0["closed"] + 1
        assert status["buffers_released"] > status0["buffers_released"]
        assert sum(s.closed for s in sessions) == 1, "exactly the closed socket's session is closed"
        await moves_exactly(a, page_a, viewer, bunny_at(0.2, 0.3))  # the other socket's session goes on
        await a.close()
    run(test, viewer)


def test_estimator_and_photons_from_the_page_equal_a_fresh_session(viewer):
    async def test(client):
        ws, page, _ = await connect(client, viewer)
        await move(ws, bunny_at(0.4, 0.0))
        await ws.send_str(json.dumps({"type": "estimator", "radius": 0.1, "method": "detp"}))
        await ws.send_str(json.dumps({"type": "photons", "count": 12_000}))
        done = await sync(ws, page)
        assert done["method"] == "detp" and done["radius"] == 0.1 and done["photons"] == 12_000
        ref = reference_colours(viewer, done["poses"], method="detp", radius=0.1, photons=12_000)
        assert page.shows(ref)
        await ws.close()
    run(test, viewer)


def test_frame_encoder_sends_changed_runs_as_float16():
    from oclgi.viewer.vertex_colours import FrameEncoder

    rng = np.random.default_rng(3)
    enc, page = FrameEncoder(100), PageModel(100)
    c = rng.random((100, 3), dtype=np.float32) * 40
    first = enc.frame(c, 0)
    assert len(first) == 24 + 6 * 100  # the first frame: every colour
    page.apply(first)
    assert page.e == 6 - 12 and page.shows(c)  # the largest colour (32 to 40) near 2^12 after scaling
    assert np.abs(page.colours - c).max() <= 2.0 ** -11 * c.max()
    assert enc.frame(c, 0) is None  # nothing new
    empty = enc.frame(c, 1)  # a new update that changed no half: a frame of no colour, carrying its seq
    assert len(empty) == 28
    page.apply(empty)
    assert page.seq == 1 and page.shows(c)
    c[[3, 50, 99], 1] += 1  # alone: three indices
    f = enc.frame(c, 2)
    assert len(f) == 28 + 4 * 3 + 6 * 3
    page.apply(f)
    assert page.shows(c)
    c[10:30] += 1  # a run, and two alone
    c[[40, 70], 0] += 1
    f = enc.frame(c, 3)
    assert len(f) == 28 + 8 + 4 * 2 + 6 * 22
    page.apply(f)
    assert page.shows(c)
    c[:60] *= 1.5  # one long run
    f = enc.frame(c, 4)
    assert len(f) == 28 + 8 + 6 * 60
    page.apply(f)
    c[np.arange(100) % 10 != 0] *= 1.5  # most changed, in ten runs: the whole array is smaller
    f = enc.frame(c, 5)
    assert len(f) == 24 + 6 * 100
    page.apply(f)
    assert page.shows(c) and page.seq == 5
    # a change below float16's step at this scale is no change on the page
    tiny = c.copy()
    tiny[5, 0] = np.nextafter(tiny[5, 0], np.float32(np.inf))
    assert len(enc.frame(tiny, 6)) == 28
    # a colour that would overflow float16 at this scale: a new scale, the whole array again
    c[7] = 3e6
    f = enc.frame(c, 7)
    assert len(f) == 24 + 6 * 100
    page.apply(f)
    assert page.e == 22 - 12 and page.shows(c) and np.isfinite(page.colours).all()
    assert np.abs(page.colours[7] - 3e6).max() <= 2.0 ** -11 * 3e6


def test_sparse_frames_cost_less_than_the_per_index_float32_ones(viewer):
    """A move's frame: the bunny's vertices one run, the floor's changes few runs (the tessellation keeps a
    triangle's cut vertices together); at most the old format's size (16 + 16 bytes per changed vertex,
    or 12 per vertex whole), about half of it or less."""
    from oclgi.viewer.vertex_colours import FrameEncoder

    enc = FrameEncoder(len(viewer.tess.vertices))
    enc.frame(reference_colours(viewer, {}), 0)
    moved = reference_colours(viewer, {"bunny": bunny_at(0.4, -0.1)})
    changed = (moved != reference_colours(viewer, {})).any(axis=1).sum()
    f = enc.frame(moved, 1)
    old = 16 + min(16 * changed, 12 * len(moved))
    assert len(f) <= old / 2 + 8, (len(f), old, changed)
    print(len(f), old, changed, len(moved))


def test_movable_objects_are_queried_once_per_edge_sized_cell(viewer):
    from oclgi.viewer.mesh_payload import vertex_objects
    from oclgi.viewer.object_points import object_points

    tess, scene = viewer.tess, viewer.engine.scene
    objects, _ = vertex_objects(scene, tess.vertex_tri)
    material = np.asarray(scene.tri_material)[tess.vertex_tri]
    queried, value_of = object_points(tess, objects, material)
    rep = queried[value_of]  # the vertex whose value each vertex shows
    static = objects == 0
    assert np.array_equal(rep[static], np.nonzero(static)[0]), "a static vertex shows another's value"
    moving = ~static
    assert 0 < len(np.unique(rep[moving])) < moving.sum() / 5, "the bunny's vertices were not thinned"
    assert (objects[rep] == objects).all() and (material[rep] == material).all()
    assert (np.linalg.norm(tess.vertices[rep] - tess.vertices, axis=1) <= np.sqrt(3) * tess.edge).all()
    assert ((tess.normals[rep] * tess.normals).sum(axis=1)[moving] >= 0).all(), "a value crossed to the other side"
    q, v = object_points(tess, objects, material, all_vertices=True)
    assert np.array_equal(q, np.arange(len(tess.vertices))) and np.array_equal(v, q)
    assert len(viewer.points) == len(queried)


def test_switching_to_photon_maps_and_back_opens_a_session_of_the_other_kind(viewer):
    """An estimator of the other family: a new session (Photon Maps or DETP) at the page's poses, equal to the
    API's session of that kind moved there; the old session closed."""
    async def test(client):
        ws, page, hello = await connect(client, viewer)
        assert "photon_map" in hello["methods"] and "detp" in hello["methods"]
        await move(ws, bunny_at(0.4, 0.1, 0.3))
        before = await sync(ws, page)
        opened, closed = viewer.sessions_opened, viewer.sessions_closed
        await ws.send_str(json.dumps({"type": "estimator", "method": "photon_map", "k": 20}))
        upd = await receive_until(ws, page, lambda m: m["type"] in ("update", "error"))
        assert upd["type"] == "update" and upd["switched"] and upd["method"] == "photon_map" and upd["k"] == 20
        done = await sync(ws, page)
        assert done["poses"] == before["poses"] and done["radius"] is None
        assert viewer.sessions_opened == opened + 1 and viewer.sessions_closed == closed + 1
        assert page.shows(reference_colours(viewer, done["poses"], method="photon_map", k=20))
        assert not page.shows(reference_colours(viewer, done["poses"]))
        # within the family: k by set_estimator; a move goes on in the new session
        await ws.send_str(json.dumps({"type": "estimator", "k": 12}))
        await move(ws, bunny_at(0.2, 0.3))
        done = await sync(ws, page, 2)
        assert done["k"] == 12 and done["method"] == "photon_map"
        # a Photon Map session's move is the practical update (it depends on the way taken): the API's session
        # takes the same steps
        from oclgi.incremental.open_session import open_session

        with open_session(viewer.engine, viewer.points, method="photon_map", photons=PHOTONS, k=20) as s:
            s.move("bunny", np.reshape(before["poses"]["bunny"], (4, 4)))
            s.set_estimator("photon_map", k=12)
            s.move("bunny", np.reshape(done["poses"]["bunny"], (4, 4)))
            assert page.shows(viewer.colours(s.irradiance()))
        # and back to DETP, radius given
        await ws.send_str(json.dumps({"type": "estimator", "method": "detp", "radius": 0.08}))
        done = await sync(ws, page, 3)
        assert done["method"] == "detp" and done["radius"] == 0.08 and done["k"] is None
        assert page.shows(reference_colours(viewer, done["poses"], method="detp", radius=0.08))
        await ws.close()
    run(test, viewer)


CAMERA = {"position": [0.3, 1.1, 3.5], "look_at": [0.0, 0.9, 0.0], "up": [0, 1, 0], "fov": 42.0}


async def render(ws, page, ident, width=24, height=16, plain=None):
    """Ask for a render; (the rendered message, the progress messages, png bytes, radiance)."""
    await ws.send_str(json.dumps({"type": "render", "id": ident, "camera": CAMERA, "width": width,
                                  "height": height, **({} if plain is None else {"plain": plain})}))
    seen = len(page.messages)
    done = await receive_until(ws, page, lambda m: m["type"] in ("rendered", "error"))
    assert done["type"] == "rendered", done
    progress = [m for m in page.messages[seen:] if m["type"] == "render_progress" and m["id"] == ident]
    data = await ws.receive_bytes(timeout=120)
    magic, index, w, h, n = struct.unpack_from("<4sIIII", data)
    assert magic == b"OGVR" and index == done["index"] and (w, h) == (width, height)
    png = data[20:20 + n]
    radiance = np.frombuffer(data, "<f4", offset=20 + n).reshape(h, w, 3)
    return done, progress, png, radiance


def test_a_render_takes_the_commands_default_and_a_gathered_one_past_64x64_its_own_process(viewer):
    from oclgi.viewer.render_process import IN_PROCESS_GATHERED, IN_PROCESS_PIXELS, elsewhere, render_args

    detp = viewer.engine.run_params("detp_disc_index", 1000, 0.03, 1, 8, None, None)
    args = render_args(detp, {}, 64, 64, plain=False)
    assert args["spp"] == 16 and args["direct"] == "exact" and args["gather"] == 128 and args["radius"] == 0.03
    assert not elsewhere(64, 64, args) and 64 * 64 == IN_PROCESS_GATHERED
    assert elsewhere(65, 64, render_args(detp, {}, 65, 64, plain=False))
    plain = render_args(detp, {}, 65, 64, plain=True)
    assert "spp" not in plain and "gather" not in plain and not elsewhere(65, 64, plain)
    assert elsewhere(IN_PROCESS_PIXELS + 1, 1, plain)
    # Photon Maps and a run that counts no emitted light keep the method's own estimate
    pm = viewer.engine.run_params("photon_map", 1000, None, 1, 8, None, None)
    assert render_args(pm, {"k": 8}, 64, 64, plain=False) == dict(method="photon_map", photons=1000, seed=1,
                                                                  max_depth=8, k=8)
    dark = viewer.engine.run_params("detp_disc_index", 1000, 0.03, 1, 8, None, False)
    assert "gather" not in render_args(dark, {}, 64, 64, plain=False)


@pytest.mark.parametrize("where,plain", [("server", False), ("process", False), ("server", True)])
def test_render_this_view_equals_the_api_render_at_the_camera_and_pose(viewer, where, plain, monkeypatch):
    """In the server's process, or (large renders, oclgi/viewer/render_process.py) in one of its own;
    with ``oclgi render``'s default estimate, or (``plain``) the photons' estimate alone."""
    import oclgi
    import oclgi.viewer.render_process as render_process
    from oclgi.estimators.render_preset import render_settings
    from oclgi.io import png_bytes

    if where == "process":
        monkeypatch.setattr(render_process, "IN_PROCESS_PIXELS", 0)

    async def test(client):
        ws, page, _ = await connect(client, viewer)
        await move(ws, bunny_at(0.5, -0.2, 0.4))
        posed = await sync(ws, page)
        done, progress, png, radiance = await render(ws, page, 7, plain=plain or None)
        assert progress and progress[-1]["traced"] == progress[-1]["paths"] == PHOTONS
        assert [m["stage"] for m in progress].count("final") == 1 and progress[-1]["stage"] == "final"
        assert all(m["stage"] == "photons" for m in progress[:-1]) and len(progress) >= 2
        engine = viewer.engine.posed()
        engine.place("bunny", np.array(posed["poses"]["bunny"]).reshape(4, 4))
        cam = oclgi.Camera(position=tuple(CAMERA["position"]), look_at=tuple(CAMERA["look_at"]), fov=CAMERA["fov"],
                           width=24, height=16)
        r = viewer.run
        args = dict(method=r.method, photons=r.photons, radius=r.radius, seed=r.seed, max_depth=r.max_depth)
        preset = {} if plain else render_settings("detp", {}, False, 24, 16)
        assert plain or preset["spp"] == 16 and preset["gather"] > 0
        api = engine.render(cam, **args, **preset)
        assert np.array_equal(radiance, api.radiance), "the render is not the API's at that camera and pose"
        if not plain:  # the default estimate, not the photons' alone
            assert not np.array_equal(radiance, engine.render(cam, **args).radiance)
        assert png == png_bytes(api.pixels) and api.radiance.max() > 0
        # the session is untouched: still exact, still moving
        after = await sync(ws, page, 2)
        assert after["seq"] == posed["seq"]
        await moves_exactly(ws, page, viewer, bunny_at(0.1, 0.1), 3)
        await ws.close()
    run(test, viewer)
