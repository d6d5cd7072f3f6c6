"""Who may talk to ``oclgi view`` (oclgi/viewer/guard.py), tried as a hostile
web page would: a WebSocket with the headers a browser sends from another
origin, or from ``null``, or without the token, is refused; so is any HTTP
request whose Host is not this server's (DNS rebinding) and the scene
without the token. The server's own page, with its token, gets in; each
refusal is one line of the server's log."""

import asyncio

import pytest
from aiohttp import WSServerHandshakeError
from aiohttp.test_utils import TestClient, TestServer  # aiohttp: setup.cfg's test extra
from viewer_client import open_viewer

from oclgi.errors import OclgiError
from oclgi.viewer.guard import Guard, check_origins


@pytest.fixture(scope="module")
def viewer(scenes_dir):
    return open_viewer(scenes_dir / "cornell_box.toml", photons=2_000, edge=0.6)


def _run(viewer, test, allow=()):
    said = []
    viewer.guard = Guard("127.0.0.1", viewer.guard.token, check_origins(allow), log=said.append)

    async def main():
        async with TestClient(TestServer(viewer.app())) as client:
            await test(client, client.server.port, viewer.guard.token)

    asyncio.run(main())
    return said


async def _socket(client, path, **headers):
    """The status of a WebSocket handshake (101 when it opened; the socket is closed again)."""
    try:
        ws = await client.ws_connect(path, headers=headers)
    except WSServerHandshakeError as exc:
        return exc.status
    await ws.close()
    return 101


def test_foreign_and_null_origins_and_missing_tokens_are_refused(viewer):
    got = {}

    async def test(client, port, token):
        own = f"http://127.0.0.1:{port}"
        got["evil"] = await _socket(client, f"/socket?token={token}", Origin="http://evil.example")
        got["null"] = await _socket(client, f"/socket?token={token}", Origin="null")
        got["lookalike"] = await _socket(client, f"/socket?token={token}",
                                         Origin=f"http://127.0.0.1.evil.example:{port}")
        got["other port"] = await _socket(client, f"/socket?token={token}", Origin=f"http://127.0.0.1:{port + 1}")
        got["no token"] = await _socket(client, "/socket", Origin=own)
        got["wrong token"] = await _socket(client, "/socket?token=" + "x" * len(token), Origin=own)
        got["own"] = await _socket(client, f"/socket?token={token}", Origin=own)
        got["localhost"] = await _socket(client, f"/socket?token={token}", Origin=f"http://localhost:{port}")
        got["script"] = await _socket(client, f"/socket?token={token}")  # no Origin: not a web page

    said = _run(viewer, test)
    assert got == {"evil": 403, "null": 403, "lookalike": 403, "other port": 403, "no token": 403,
                   "wrong token": 403, "own": 101, "localhost": 101, "script": 101}, got
    assert len(said) == 6 and all(line.startswith("oclgi view: refused GET /socket from ") for line in said), said
    assert "Origin 'http://evil.example' is not this server's page" in said[0]
    assert "no token" in said[4] and "a wrong token" in said[5]


def test_a_foreign_host_gets_403_and_the_scene_needs_the_token(viewer):
    got = {}

    async def test(client, port, token):
        for name, path, host in [("rebinding scene", f"/scene.json?token={token}", f"evil.example:{port}"),
                                 ("rebinding mesh", f"/mesh.bin?token={token}", f"evil.example:{port}"),
                                 ("rebinding static", "/static/viewer.js", f"evil.example:{port}"),
                                 ("no host port", f"/scene.json?token={token}", "127.0.0.1"),
                                 ("scene without token", "/scene.json", None),
                                 ("page without token", "/", None),
                                 ("status without token", "/status.json", None),
                                 ("page", f"/?token={token}", None),
                                 ("scene", f"/scene.json?token={token}", f"localhost:{port}"),
                                 ("scene by header", "/scene.json", None),
                                 ("static", "/static/viewer.js", None)]:
            headers = {"Host": host} if host else {}
            if name == "scene by header":
                headers["Authorization"] = f"token {token}"
            async with client.get(path, headers=headers) as r:
                got[name] = r.status
                body = await r.read()
                if r.status == 403:
                    assert body.startswith(b"oclgi view: refused: ")

    _run(viewer, test)
    assert got == {"rebinding scene": 403, "rebinding mesh": 403, "rebinding static": 403, "no host port": 403,
                   "scene without token": 403, "page without token": 403, "status without token": 403,
                   "page": 200, "scene": 200, "scene by header": 200, "static": 200}, got


def test_allow_origin_lets_another_origin_in(viewer):
    got = {}

    async def test(client, port, token):
        got["allowed"] = await _socket(client, f"/socket?token={token}", Origin="http://192.168.7.5:8765")
        got["other"] = await _socket(client, f"/socket?token={token}", Origin="http://192.168.7.5:8766")

    _run(viewer, test, allow=["http://192.168.7.5:8765/"])
    assert got == {"allowed": 101, "other": 403}


def test_bad_allow_origin_values_are_one_line():
    for bad in ("192.168.7.5", "ftp://x:1", "http://x:1/path", "http://x:99999"):
        with pytest.raises(OclgiError, match="--allow-origin"):
            check_origins([bad])


def test_the_printed_url_carries_the_token(scenes_dir):
    viewer = open_viewer(scenes_dir / "cornell_box.toml", photons=2_000, edge=0.6)  # serving ends it
    urls = []

    async def main():
        task = asyncio.create_task(viewer.serve("127.0.0.1", 0, urls.append))
        while not urls:
            await asyncio.sleep(0.01)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(main())
    base, query = urls[0].split("?")
    assert base.startswith("http://127.0.0.1:") and query == f"token={viewer.guard.token}"
    assert len(viewer.guard.token) >= 32
