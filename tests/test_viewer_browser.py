"""``oclgi view`` end to end in headless Chromium (Debian's chromium,
tools/ensure-chromium.sh; driven over the DevTools protocol, tests/browser.py):
the page loads, the bunny is dragged across the Cornell box floor with the
mouse, drawn at a level of detail while it moves (the page told its frames
are slow), the colours the page draws at rest change where the light
changed and equal the API's at that pose, and the level's the averaging of
those; orbiting redraws without a server update; a page told its frames
are fast never leaves the full mesh; a second tab has its own session and
closing it frees that session; the bake downloads; Ctrl-C stops the
server. Screenshots are kept in the test's tmp dir."""

import asyncio
import json
import os
import signal
import subprocess
import sys
import urllib.request

import numpy as np
import pytest

from browser import Browser, chromium_path
from viewer_client import EDGE, PHOTONS, as_shown, open_viewer, reference_colours


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    """The same scene, tessellation and run as the server's: the API's side."""
    v = open_viewer(scenes_dir / "cornell_bunny.toml")
    yield v
    v.executor.shutdown(wait=True)


@pytest.fixture
def server(scenes_dir):
    def as_a_terminal_job():
        # Ctrl-C at its default, as a terminal gives it, whatever this test
        # process inherited or earlier tests left (an ignored SIGINT is kept
        # ignored by oclgi, as nohup asks: the server would never stop).
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    proc = subprocess.Popen([sys.executable, "-m", "oclgi", "view", str(scenes_dir / "cornell_bunny.toml"),
                             "--port", "0", "--photons", str(PHOTONS), "--edge", str(EDGE), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=dict(os.environ),
                            preexec_fn=as_a_terminal_job)
    url = proc.stdout.readline().strip()
    assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if proc.poll() is not None else "")
    yield proc, url
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def status(url) -> dict:
    base, token = url.split("?", 1)  # the printed URL carries the server's token
    with urllib.request.urlopen(f"{base}status.json?{token}", timeout=10) as r:
        return json.load(r)


async def colours(tab) -> tuple[np.ndarray, int]:
    """The float16 bits the page holds (V, 3) and their scale's exponent."""
    shown = np.array(await tab.eval("Array.from(oclgiState.colours)"), np.float32).reshape(-1, 3)
    half = shown.astype(np.float16)
    assert np.array_equal(half.astype(np.float32), shown), "the page holds values that are no float16"
    return half.view(np.uint16), await tab.eval("oclgiState.scaleExponent")


async def shows(tab, api: np.ndarray) -> bool:
    """The page holds the API's colours rounded to float16 at its scale, bit for bit."""
    half, e = await colours(tab)
    return np.array_equal(half, as_shown(api, e))


async def drag(tab, start, end, steps=12):
    await tab.mouse("mousePressed", *start)
    for i in range(1, steps + 1):
        t = i / steps
        await tab.mouse("mouseMoved", start[0] + t * (end[0] - start[0]), start[1] + t * (end[1] - start[1]))
        await asyncio.sleep(0.03)
    await tab.mouse("mouseReleased", *end)


def render_at(viewer, poses, request) -> np.ndarray:
    """The API's render radiance at ``poses`` from the camera a page asks for,
    with ``oclgi render``'s default estimate (the page's unless it ticks "plain")."""
    import oclgi
    from oclgi.estimators.render_preset import render_settings

    engine = viewer.engine.posed()
    for name, m in poses.items():
        engine.place(name, np.array(m).reshape(4, 4))
    c = request["camera"]
    cam = oclgi.Camera(position=tuple(c["position"]), look_at=tuple(c["look_at"]), up=tuple(c["up"]), fov=c["fov"],
                       width=request["width"], height=request["height"])
    r = viewer.run
    preset = {} if request["plain"] else render_settings("detp", {}, False, request["width"], request["height"])
    return engine.render(cam, method=r.method, photons=r.photons, radius=r.radius, seed=r.seed,
                         max_depth=r.max_depth, **preset).radiance


def test_view_in_headless_chromium(viewer, server, tmp_path):
    assert chromium_path(), "chromium is missing: tools/ensure-chromium.sh (make test runs it) installs it"
    proc, url = server
    home = reference_colours(viewer, {})
    static = viewer.tess.vertex_tri < viewer.engine.scene.object_ranges()[0][1]

    async def main():
        async with Browser() as browser:
            tab = await browser.open(url)
            await tab.wait("window.oclgiState && oclgiState.ready && oclgiState.frames > 0 && oclgiState.draws > 1")
            shown, e0 = await colours(tab)
            assert np.array_equal(shown, as_shown(home, e0)), "the first frame is not the API's solution"
            await tab.screenshot(tmp_path / "loaded.png")
            measured = await tab.eval("oclgiState.frameMs")
            assert measured["full"] is not None and measured["full"] > 0, measured
            assert await tab.eval("oclgiState.api.levels()") == len(viewer.levels) >= 1
            assert await tab.eval("oclgiState.api.frameTimes(100, [100, 1])") == 1  # a slow browser: level 1

            # drag the bunny with the mouse, from its middle to the right across the floor
            box = await tab.eval("oclgiState.api.objectBox(0)")
            start = await tab.eval(f"oclgiState.api.project({json.dumps(box['centre'])})")
            picked = await tab.eval(f"oclgiState.api.pick({start[0]}, {start[1]})")
            assert picked == 1, "the bunny is not under the mouse"
            goal = [box["centre"][0] + 0.8, box["centre"][1], box["centre"][2] - 0.3]
            end = await tab.eval(f"oclgiState.api.project({json.dumps(goal)})")
            await drag(tab, start, end)
            synced = await tab.eval("oclgiState.api.sync()")
            await tab.wait(f"oclgiState.fullSeq === {synced['seq']} && oclgiState.drawnLevel === 0 && "
                           f"oclgiState.drawnSeq === {synced['seq']}")  # at rest: the tessellation again
            assert (await tab.eval("oclgiState.drawsByLevel"))[1] > 0, "the drag did not draw the level of detail"
            # a pose alone, while its move's answer is on its way, waits at least MOTION_INTERVAL_MS after the
            # frame before
            interval = await tab.eval("MOTION_INTERVAL_MS")
            assert interval >= 50 and all(g >= interval for g in await tab.eval("oclgiState.poseGaps"))
            assert (await tab.eval("oclgiState.levelSeqs"))[1] >= 0, "no frame of the level came during the drag"
            pose = np.array(synced["poses"]["bunny"]).reshape(4, 4)
            assert pose[0, 3] > 0.5 and abs(pose[1, 3]) < 1e-6, f"the bunny did not slide along the floor: {pose}"
            moved, e = await colours(tab)
            api = reference_colours(viewer, synced["poses"])
            assert e == e0 and np.array_equal(moved, as_shown(api, e)), \
                "the page's colours are not the API's at the dragged pose (to float16)"
            changed = (moved != shown).any(axis=1)
            light_changed = (as_shown(api, e) != as_shown(home, e)).any(axis=1)
            assert np.array_equal(changed, light_changed)
            assert changed[static].sum() > 50, "the floor's light did not follow the bunny"
            await tab.screenshot(tmp_path / "dragged.png")
            await tab.eval("oclgiState.api.orbit(0.001, 0)")  # in motion: the level, its colours at this pose
            await tab.wait(f"oclgiState.levelSeqs[1] === {synced['seq']} && oclgiState.drawnLevel === 1")
            level = await tab.eval("oclgiState.api.levelColours(1)")
            lv = np.array(level["colours"], np.float32).reshape(-1, 3)
            assert np.array_equal(lv.astype(np.float16).view(np.uint16),
                                  as_shown(viewer.levels[0].colours(api), level["e"])), \
                "the level's colours are not the averaging of the API's at the pose"
            await tab.wait("oclgiState.drawnLevel === 0")  # rests again

            # orbit: the view changes, the server computes nothing
            updates = await tab.eval("oclgiState.updates")
            before = (tmp_path / "dragged.png").read_bytes()
            await drag(tab, (60, 60), (130, 80))
            await tab.wait("oclgiState.draws > 0")
            await asyncio.sleep(0.3)
            await tab.screenshot(tmp_path / "orbited.png")
            assert (tmp_path / "orbited.png").read_bytes() != before, "orbiting did not change the view"
            assert await tab.eval("oclgiState.updates") == updates
            again = await tab.eval("oclgiState.api.sync()")
            assert again["updates"] == synced["updates"], "orbiting made the server update"

            # a second tab: a session of its own, at the pose as loaded; closing it frees it
            tab2 = await browser.open(url)
            await tab2.wait("window.oclgiState && oclgiState.ready && oclgiState.frames > 0")
            assert status(url)["open"] == 2
            assert await shows(tab2, home)
            assert np.array_equal((await colours(tab))[0], moved)
            released = status(url)["buffers_released"]
            await tab2.close()
            for _ in range(200):
                s = status(url)
                if s["closed"] == 1:
                    break
                await asyncio.sleep(0.05)
            assert s["open"] == 1 and s["closed"] == 1 and s["buffers_released"] > released
            assert (await tab.eval("oclgiState.api.sync()"))["poses"] == synced["poses"]

            # "render this view": the engine's image from the page's camera at the dragged pose
            request = await tab.eval("oclgiState.api.renderCamera(32)")
            assert request["plain"] is False  # the command's default estimate unless the page asks
            got = await tab.eval("oclgiState.api.render(32).then(r => ({w: r.width, h: r.height, png: r.png.length, "
                                 "radiance: Array.from(r.radiance)}))")
            assert await tab.eval("document.querySelector('#render-result img') !== null")
            assert got["png"] > 0 and (got["w"], got["h"]) == (32, request["height"])
            api = render_at(viewer, synced["poses"], request)
            assert np.array_equal(np.array(got["radiance"], np.float32).reshape(api.shape), api)

            # Photon Maps from the estimator control: a session of the other kind at the same pose
            await tab.eval("document.getElementById('method').value = 'photon_map'; "
                           "document.getElementById('apply').click()")
            await tab.wait("oclgiState.session.method === 'photon_map'")
            pm = await tab.eval("oclgiState.api.sync()")
            await tab.wait(f"oclgiState.drawnSeq === {pm['seq']}")
            assert pm["poses"] == synced["poses"] and pm["k"] is not None
            assert await shows(tab, reference_colours(viewer, pm["poses"], method="photon_map", k=pm["k"]))

            # a fast browser (a GPU's): the full mesh all along, no frame of a level asked for
            assert await tab.eval("oclgiState.api.frameTimes(1)") == 0
            level_draws = (await tab.eval("oclgiState.drawsByLevel"))[1]
            level_seq = (await tab.eval("oclgiState.levelSeqs"))[1]

            # the gizmo: the square above the bunny raises it, the ring beside it turns it
            await tab.eval("oclgiState.api.select(1)")
            g = await tab.eval("oclgiState.api.gizmoPoints(0)")
            at = await tab.eval(f"oclgiState.api.project({json.dumps(g['height'])})")
            await drag(tab, at, (at[0], at[1] - 40), steps=6)
            raised = await tab.eval("oclgiState.api.sync()")
            before, after = np.reshape(pm["poses"]["bunny"], (4, 4)), np.reshape(raised["poses"]["bunny"], (4, 4))
            assert after[1, 3] > before[1, 3] + 0.01 and np.allclose(after[[0, 2], 3], before[[0, 2], 3], atol=1e-6)
            assert np.allclose(after[:3, :3], before[:3, :3], atol=1e-6)
            g = await tab.eval("oclgiState.api.gizmoPoints(0)")
            at = await tab.eval(f"oclgiState.api.project({json.dumps(g['turn'])})")
            c = await tab.eval(f"oclgiState.api.project({json.dumps(g['centre'])})")
            r = np.hypot(at[0] - c[0], at[1] - c[1])
            await drag(tab, at, (c[0], c[1] - r), steps=6)  # a quarter turn on screen
            turned = await tab.eval("oclgiState.api.sync()")
            m = np.reshape(turned["poses"]["bunny"], (4, 4))
            angle = np.arctan2(m[0, 2], m[0, 0]) - np.arctan2(after[0, 2], after[0, 0])
            assert abs(angle) > 0.3 and np.isclose(m[1, 3], after[1, 3], atol=1e-6), m
            assert turned["updates"] > raised["updates"] > pm["updates"]
            assert (await tab.eval("oclgiState.drawsByLevel"))[1] == level_draws
            assert (await tab.eval("oclgiState.levelSeqs"))[1] == level_seq

            # "bake this pose": a glTF download of the mesh at the turned pose
            baked = await tab.eval("oclgiState.api.bake().then(b => ({n: b.glb.length, seq: b.seq, "
                                   "magic: String.fromCharCode(...b.glb.slice(0, 4))}))")
            assert baked["magic"] == "glTF" and baked["n"] > 1000 and baked["seq"] == turned["seq"]
            assert await tab.eval("document.querySelector('#bake-result a[download$=\".glb\"]') !== null")
            assert not await tab.eval("oclgiState.errors.length")

    asyncio.run(main())
    proc.send_signal(signal.SIGINT)
    try:  # the sockets' close handshakes and the device thread's last calls come first (seconds)
        status_code = proc.wait(timeout=90)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError(f"the server did not stop within 90 s of Ctrl-C: {proc.communicate()[1][-2000:]}")
    assert status_code == 130
    err = proc.stderr.read()
    assert err.strip().splitlines()[-1] == "oclgi: interrupted" and "Traceback" not in err, err
