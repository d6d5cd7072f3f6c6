"""Dragging a light from the viewer's socket (oclgi/viewer/connection.py):
at the scene file's precomputed positions by the light session's reuse,
elsewhere recomputed, after an object moved by the session itself; each
update says which, and the page equals the API's solution in each case."""

import json

import numpy as np
import pytest

from viewer_client import PHOTONS, PageModel, open_viewer, receive_until, reference_colours, run_pages, sync

PATH = [[-0.4, 1.6, 0.1], [0.3, 1.7, -0.2], [0.0, 1.5, 0.4]]
FREE = (0.2, 1.4, 0.2)


@pytest.fixture(scope="module")
def viewer(scenes_dir, tmp_path_factory):
    """The Cornell box lit by a point light alone (the ceiling's lamp dark), the bunny movable."""
    text = (f'name = "lit bunny"\n[[mesh]]\npath = "{scenes_dir / "cornell-box/CornellBox-Original.obj"}"\n'
            '[mesh.materials.light]\nemission = [0, 0, 0]\n'
            f'[[mesh]]\npath = "{scenes_dir / "stanford-bunny/bun_zipper.ply"}"\nname = "bunny"\nmovable = true\n'
            'albedo = [0.8, 0.8, 0.8]\ntransform = { scale = 4.0, translate = [-0.5, -0.13, 0.55] }\n'
            '[[point_light]]\nname = "lamp"\nposition = [0, 1.5, 0]\nintensity = [2, 1.8, 1.5]\n'
            f'path = {json.dumps(PATH)}\n'
            '[photons]\nseed = 1\nmax_depth = 8\n[estimator]\nmethod = "detp_disc_index"\nradius = 0.06\n')
    path = tmp_path_factory.mktemp("lit") / "lit_bunny.toml"
    path.write_text(text)
    v = open_viewer(path)
    yield v
    v.executor.shutdown(wait=True)


async def light(ws, page, position, ident):
    await ws.send_str(json.dumps({"type": "light", "light": "lamp", "position": list(position)}))
    upd = await receive_until(ws, page, lambda m: m["type"] in ("update", "error"))
    assert upd["type"] == "update" and upd["kind"] == "light", upd
    return upd, await sync(ws, page, ident)


def light_session_colours(viewer, position):
    from oclgi.incremental.light_session import LightSession

    r = viewer.run
    with LightSession(viewer.engine, viewer.points, light="lamp", photons=r.photons, seed=r.seed,
                      max_depth=r.max_depth, method=r.method, radius=r.radius) as s:
        assert s.move_light(position).reused
        return viewer.colours(s.irradiance())


BUNNY = [1, 0, 0, 0.4, 0, 1, 0, 0, 0, 0, 1, -0.1, 0, 0, 0, 1]


def test_a_light_dragged_by_reuse_on_its_path_recomputed_elsewhere_and_after_a_move(viewer):
    async def test(client):
        ws = await client.ws_connect("/socket")
        page = PageModel(len(viewer.tess.vertices))
        hello = await receive_until(ws, page, lambda m: m["type"] == "hello")
        assert hello["lights"] == {"lamp": [0.0, 1.5, 0.0]} and hello["shown_by"] == "session"
        key = "light.lamp.position"
        # on the path: the light session's reuse, nothing traced
        upd, done = await light(ws, page, PATH[1], 1)
        assert upd["by"] == "light session" and upd["reused"] and upd["frame"] == 1 and upd["paths_traced"] == 0
        assert done["lights"]["lamp"] == PATH[1] and done["shown_by"] == "light session"
        assert page.shows(light_session_colours(viewer, PATH[1]))
        on_path = page.half.copy()
        # off the path: recomputed (the light session's ordinary run), a fresh session's sums with the light there
        upd, done = await light(ws, page, FREE, 2)
        assert upd["by"] == "light session" and not upd["reused"] and upd["paths_traced"] == PHOTONS
        assert page.shows(reference_colours(viewer, {}, lights={key: FREE}))
        assert (page.half != on_path).any(axis=1).mean() > 0.5, "the light's move changed little"
        # back on the path
        upd, done = await light(ws, page, PATH[2], 3)
        assert upd["reused"] and upd["frame"] == 2
        assert page.shows(light_session_colours(viewer, PATH[2]))
        # an object moves: the session takes the light where it is, then moves the bunny
        await ws.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": BUNNY}))
        done = await sync(ws, page, 4)
        assert done["shown_by"] == "session"
        assert page.shows(reference_colours(viewer, done["poses"], lights={key: tuple(PATH[2])}))
        # with the bunny moved the stored light paths no longer apply: the session recomputes, and says why
        upd, done = await light(ws, page, PATH[0], 5)
        assert upd["by"] == "session" and not upd["reused"] and "object moved" in upd["why"]
        assert page.shows(reference_colours(viewer, done["poses"], lights={key: tuple(PATH[0])}))
        # bad light messages: one clear error each, the session as it was
        before = page.half.copy()
        for msg, word in (({"type": "light", "light": "sun", "position": FREE}, "no point or spot light"),
                          ({"type": "light", "light": "lamp", "position": [0, float("nan"), 0]}, "finite"),
                          ({"type": "light", "light": "lamp", "position": [0, 1]}, "3 finite numbers"),
                          ({"type": "light", "light": "lamp", "position": [0, 1e9, 0]}, "beyond"),
                          ({"type": "light", "light": 3, "position": FREE}, "no point or spot light")):
            await ws.send_str(json.dumps(msg))
            err = await receive_until(ws, page, lambda m: m["type"] in ("error", "update"))
            assert err["type"] == "error" and word in err["message"], (msg, err)
        after = await sync(ws, page, 6)
        assert after["seq"] == done["seq"] and after["lights"] == done["lights"]
        assert np.array_equal(page.half, before)
        await ws.close()
    run_pages(viewer, test)
