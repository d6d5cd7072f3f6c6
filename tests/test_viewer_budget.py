"""One memory budget for every page of ``oclgi view`` (oclgi/viewer/ledger.py),
a bound on the pages, and renders that share the device: a page's request
past the budget gets an error naming it and its session stays as it was,
exact; a page past ``--max-pages`` is told and closed; while one page
renders, another page's move is answered between the render's batches, and
a page that goes away stops its render."""

import asyncio
import json
import time

import numpy as np
import pytest
from viewer_client import connect, open_viewer, receive_until, reference_colours, run_pages, sync

from oclgi.errors import OclgiError
from oclgi.viewer.ledger import Ledger, parse_size, session_bytes

PHOTONS = 5_000


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    return open_viewer(scenes_dir / "cornell_bunny.toml", photons=PHOTONS, edge=0.4)


def _given_back(viewer):
    """Every page's share of the budget given back: the sessions close on the
    device's thread, after the work it was doing when the pages went."""
    for _ in range(200):
        if not viewer.ledger.held:
            return
        time.sleep(0.05)
    raise AssertionError(f"still booked: {viewer.ledger.held}")


def test_the_ledger_books_and_refuses_by_the_limit():
    one = session_bytes(PHOTONS, 10, 1000)
    ledger = Ledger(int(2.5 * one), max_pages=2)
    ledger.book("a", one, "a session")
    ledger.book("b", one, "a session")
    with pytest.raises(OclgiError, match=r"memory budget of .* \(--memory\)"):
        ledger.book("c", one, "a session")
    assert set(ledger.held) == {"a", "b"}  # a refusal changes nothing
    ledger.book("a", 1, "a smaller session")  # a key's new size replaces its old one
    ledger.book("c", one, "a session")
    ledger.release_page("a")
    assert set(ledger.held) == {"b", "c"}
    with pytest.raises(OclgiError, match="at most 2 pages"):
        ledger.check_page(2)
    assert parse_size("8G") == 8 << 30 and parse_size("512MiB") == 512 << 20 and parse_size(3 << 20) == 3 << 20
    for bad in ("0", "-1G", "lots", "1K", "nan"):
        with pytest.raises(OclgiError, match="--memory"):
            parse_size(bad)


def test_pages_past_the_budget_get_an_error_and_stay_exact(viewer):
    """Room for one session and a half: the first page opens, a second is
    refused at its opening, the first's request for more photons is refused
    (its colours stay those of the API at its count), fewer are taken."""
    one = session_bytes(PHOTONS, viewer.run.max_depth, len(viewer.points))
    saved = viewer.ledger
    viewer.ledger = Ledger(int(1.5 * one))
    home = reference_colours(viewer, {})
    try:
        async def test(client):
            ws, page, hello = await connect(client, viewer)
            assert hello["type"] == "hello"
            ws2, _, refused = await connect(client, viewer)
            assert refused["type"] == "error" and "memory budget" in refused["message"], refused
            more = next(n for n in range(PHOTONS, 100 * PHOTONS, PHOTONS)
                        if session_bytes(n, viewer.run.max_depth, len(viewer.points)) > viewer.ledger.limit)
            await ws.send_str(json.dumps({"type": "photons", "count": more}))
            err = await receive_until(ws, page, lambda m: m["type"] == "error")
            assert "memory budget" in err["message"] and "--memory" in err["message"]
            state = await sync(ws, page)
            assert state["photons"] == PHOTONS and page.shows(home)  # as it was, exact
            await ws.send_str(json.dumps({"type": "photons", "count": PHOTONS // 2}))
            await receive_until(ws, page, lambda m: m["type"] == "update")
            assert viewer.ledger.held[next(iter(viewer.ledger.held))] < one
            await ws.close()
            await ws2.close()

        run_pages(viewer, test)
        _given_back(viewer)
    finally:
        viewer.ledger = saved


def test_a_page_past_max_pages_is_told_and_closed(viewer):
    saved = viewer.ledger
    viewer.ledger = Ledger(saved.limit, max_pages=1)
    try:
        async def test(client):
            ws, _, hello = await connect(client, viewer)
            ws2, _, refused = await connect(client, viewer)
            assert hello["type"] == "hello" and refused["type"] == "error"
            assert "at most 1 pages at once (--max-pages)" in refused["message"]
            msg = await ws2.receive(timeout=30)
            assert msg.type.name in ("CLOSE", "CLOSED", "CLOSING")
            await ws.close()

        run_pages(viewer, test)
    finally:
        viewer.ledger = saved


@pytest.mark.parametrize("where", ["server", "process"])
def test_another_pages_move_is_answered_during_a_render_and_a_closed_page_stops_its_render(viewer, where,
                                                                                            monkeypatch):
    """A render in the server's process yields between its batches; one in a
    process of its own (oclgi/viewer/render_process.py) runs beside the
    server, and is killed when its page goes away."""
    import multiprocessing

    import oclgi.viewer.render_process as render_process

    if where == "process":
        monkeypatch.setattr(render_process, "IN_PROCESS_PIXELS", 0)

    async def test(client):
        ws_a, page_a, _ = await connect(client, viewer)
        ws_b, page_b, _ = await connect(client, viewer)
        # the photons' estimate alone: a gathered render of this size would always take a process
        view = {"type": "render", "id": 1, "width": 96, "height": 96, "plain": True,
                "camera": {"position": [0, 1, 3.9], "look_at": [0, 1, 0], "up": [0, 1, 0], "fov": 39.3}}
        # photons for many batches: the render's run takes the session's count, so raise it first
        await ws_a.send_str(json.dumps({"type": "photons", "count": 400_000}))
        await receive_until(ws_a, page_a, lambda m: m["type"] == "update")
        await ws_a.send_str(json.dumps(view))
        started = await receive_until(ws_a, page_a, lambda m: m["type"] in ("render_progress", "error"))
        assert started["type"] == "render_progress", started
        m = np.eye(4)
        m[:3, 3] = [0.1, 0.0, 0.0]
        await ws_b.send_str(json.dumps({"type": "move", "object": "bunny", "matrix": m.reshape(-1).tolist()}))
        await sync(ws_b, page_b, 7)
        # B's move was answered while A's render went on: A has not finished
        progress = await receive_until(ws_a, page_a, lambda m: m["type"] in ("render_progress", "rendered", "error"))
        assert progress["type"] == "render_progress", "the move waited for the whole render"
        assert progress["traced"] < progress["paths"]
        await ws_a.close()  # the render stops within a batch: the device is free again at once
        await sync(ws_b, page_b, 8)
        for _ in range(100):  # its process, if any, is gone
            if not multiprocessing.active_children():
                break
            await asyncio.sleep(0.05)
        assert not multiprocessing.active_children()
        await ws_b.close()

    run_pages(viewer, test)
    _given_back(viewer)
