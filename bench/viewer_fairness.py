"""One page's large render against another page's moves: how long a move waits.

``oclgi view``'s server (in this process, oclgi/viewer/server.py) with two
pages as sockets (tests/viewer_client.py): page A asks for a WIDTH x HEIGHT
render of the Cornell box with the bunny; while it runs, page B moves the
bunny and syncs, again and again, and each move + sync is timed (what B's
user waits for a drag to show). Then A asks again and closes its socket
mid-render: the time from the close to the close of its session (in the
device's thread, after the batch under way) says how soon the render
stopped (within a batch, oclgi/viewer/connection.py RENDER_BATCH).

``python bench/viewer_fairness.py [--size 4096] [--photons 100000]``;
prints one JSON record (the latencies' median and maximum, the render's
own time, the stop time).
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
import time
from pathlib import Path

from common import ROOT, arguments

sys.path.insert(0, str(ROOT / "tests"))
from viewer_client import PageModel, open_viewer, page_headers, receive_until, sync  # noqa: E402

CAMERA = {"position": [0.3, 1.1, 3.5], "look_at": [0.0, 0.9, 0.0], "up": [0, 1, 0], "fov": 42.0}


def bunny_at(dx: float) -> list:
    return [1, 0, 0, dx, 0, 1, 0, 0, 0, 0, 1, 0.05, 0, 0, 0, 1]


async def connect(client, viewer):
    ws = await client.ws_connect("/socket", max_msg_size=0)
    page = PageModel(len(viewer.tess.vertices))
    await receive_until(ws, page, lambda m: m["type"] == "hello")
    page.apply(await ws.receive_bytes(timeout=120))
    return ws, page


async def drain(ws, page, until):
    """Read page A's messages (progress, frames, the image) until ``until(msg)``."""
    while True:
        msg = await ws.receive(timeout=600)
        if msg.type.name == "TEXT":
            data = json.loads(msg.data)
            if until(data):
                return data
        elif msg.type.name != "BINARY":
            return None


async def main(args) -> dict:
    from aiohttp.test_utils import TestClient, TestServer

    viewer = open_viewer(Path(args.scene), photons=args.photons)
    out = {"size": args.size, "photons": args.photons, "cpus": os.cpu_count()}
    async with TestClient(TestServer(viewer.app()), headers=page_headers(viewer)) as client:
        a, pa = await connect(client, viewer)
        b, pb = await connect(client, viewer)
        # the photons' estimate alone, as recorded in bench/README.md
        render = {"type": "render", "id": 1, "camera": CAMERA, "width": args.size, "height": args.size, "plain": True}
        t0 = time.perf_counter()
        await a.send_str(json.dumps(render))
        done = asyncio.ensure_future(drain(a, pa, lambda m: m["type"] in ("rendered", "error")))
        waits, i = [], 0
        while not done.done():
            i += 1
            t = time.perf_counter()
            await b.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": bunny_at(0.01 * (i % 20))}))
            await sync(b, pb, i)
            waits.append(time.perf_counter() - t)
            await asyncio.sleep(0.05)
        rendered, waits = await done, sorted(waits)
        out.update(render_s=round(time.perf_counter() - t0, 2), rendered=rendered["type"], moves=len(waits),
                   move_sync_median_s=round(waits[len(waits) // 2], 3), move_sync_max_s=round(waits[-1], 3),
                   move_sync_p99_s=round(waits[int(0.99 * (len(waits) - 1))], 3))
        # a page that goes away mid-render: its booking goes when the render stops
        a2, pa2 = await connect(client, viewer)
        await a2.send_str(json.dumps(render))
        await drain(a2, pa2, lambda m: m["type"] == "render_progress")
        closed = viewer.sessions_closed
        t = time.perf_counter()
        await a2.close()
        while viewer.sessions_closed == closed:  # its session closes in the device's thread, after the batch
            await asyncio.sleep(0.01)
        out["stop_after_close_s"] = round(time.perf_counter() - t, 3)
        await a.close()
        await b.close()
    viewer.executor.shutdown(wait=True)
    return out


if __name__ == "__main__":
    args = arguments(__doc__, scene=str(ROOT / "scenes" / "cornell_bunny.toml"), size=4096, photons=100_000)
    print(json.dumps(asyncio.run(main(args))))
