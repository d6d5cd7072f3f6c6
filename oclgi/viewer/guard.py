"""Who may talk to ``oclgi view``: a token, the page's own origins, this server's names.

A server on 127.0.0.1 keeps other machines out but not other web pages: a
browser lets any page the user has open send requests to
``http://127.0.0.1:PORT`` and open ``ws://127.0.0.1:PORT/socket``; only the
server can refuse them. As Jupyter Server does, every server holds three
checks, each one refusing with 403 and a line in the server's log:

- **a token**: a random secret per server, in the URL the command prints
  (``http://127.0.0.1:PORT/?token=...``). The page, the scene
  (``/scene.json``, ``/mesh.bin``), ``/status.json`` and the socket need
  it (the ``token`` query parameter, or an ``Authorization: token ...``
  header); the page's own script and style (``/static/``), the same for
  every user, do not. A page elsewhere cannot read the URL, so it cannot
  drive the session nor read the scene.
- **the Host header** of every request must name this server: 127.0.0.1,
  localhost or [::1], the ``--host`` address, and, when that is a wildcard
  (0.0.0.0, ::), this machine's names and addresses; always with the port
  served. A DNS-rebinding page (evil.example resolving to 127.0.0.1)
  sends its own name, and is refused.
- **the Origin header** of the socket's handshake must be one of this
  server's origins (``http://`` and an allowed Host), or one given with
  ``--allow-origin``. Browsers always send it on a WebSocket; ``null``
  (sandboxed frames, files) is refused. A client that sends none is not a
  web page (a script with the token), and is let in.
"""

from __future__ import annotations

import hmac
import secrets
import socket
import sys
from urllib.parse import urlsplit

# The routes that need the token: the page, the scene it draws, the status and the socket.
PRIVATE = ("/", "/scene.json", "/mesh.bin", "/status.json", "/socket")
LOOPBACK = ("127.0.0.1", "localhost", "[::1]")
WILDCARDS = ("0.0.0.0", "::", "")


def new_token() -> str:
    return secrets.token_urlsafe(24)


def host_name(host: str) -> str:
    """A listening address as it appears in a Host header (IPv6 in brackets), lower case."""
    host = host.strip().lower()
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


def origin_of(text: str) -> str | None:
    """``scheme://host[:port]`` of an --allow-origin value, lower case, or None when it is not one."""
    try:
        parts = urlsplit(text.strip())
        port = parts.port
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.path not in ("", "/") \
            or parts.query or parts.fragment or parts.username or parts.password:
        return None
    name = host_name(parts.hostname)
    return f"{parts.scheme}://{name}" + (f":{port}" if port is not None else "")


def _machine_names() -> set[str]:
    """This machine's names and addresses, for a server listening on every interface."""
    names = set()
    for name in {socket.gethostname(), socket.getfqdn()}:
        if not name:
            continue
        names.add(name.lower())
        try:
            names.update(host_name(info[4][0]) for info in socket.getaddrinfo(name, None))
        except OSError:
            pass
    return names


class Guard:
    """The three checks of the module doc for a server listening on ``host``
    with ``token``; ``allow_origins``: more origins the socket accepts (their
    hosts are accepted in Host headers too)."""

    def __init__(self, host: str = "127.0.0.1", token: str | None = None, allow_origins=(), log=None):
        self.token = token or new_token()
        self.origins = set(allow_origins)
        self.log = log if log is not None else (lambda line: print(line, file=sys.stderr, flush=True))
        self.listen_on(host)

    def listen_on(self, host: str) -> None:
        """The names the server answers to when it listens on ``host``."""
        self.host = host_name(host)
        names = set(LOOPBACK) | {host_name(urlsplit(o).hostname) for o in self.origins}
        if self.host in WILDCARDS or self.host == "[::]":
            names |= _machine_names()
        else:
            names.add(self.host)
        self.names = names

    # -- the checks --------------------------------------------------------------
    def hosts(self, port: int) -> set[str]:
        """The Host header values this server answers to on ``port``."""
        out = {f"{n}:{port}" for n in self.names}
        if port == 80:
            out |= self.names
        return out

    def refusal(self, path: str, host: str | None, origin: str | None, token: str | None, port: int,
                socket_route: bool) -> str | None:
        """Why a request is refused, or None: it may go on."""
        if host is None or host.strip().lower() not in self.hosts(port):
            return (f"Host {host!r} is not this server's (it answers to 127.0.0.1:{port}, localhost:{port}"
                    + ("" if self.host in LOOPBACK else f", {self.host}:{port}") + ")")
        if socket_route and origin is not None:
            o = origin.strip().lower().rstrip("/")
            own = {f"http://{h}" for h in self.hosts(port)}
            if o not in own and o not in self.origins:
                return f"Origin {origin!r} is not this server's page (--allow-origin ORIGIN lets another in)"
        if path in PRIVATE and not (token and hmac.compare_digest(token.encode(), self.token.encode())):
            return ("no token" if not token else "a wrong token") + \
                " (open the URL `oclgi view` printed, with its ?token=...)"
        return None

    def middleware(self):
        """An aiohttp middleware refusing, with 403, every request the checks refuse."""
        from aiohttp import web

        @web.middleware
        async def guard(request, handler):
            sock = request.transport.get_extra_info("sockname") if request.transport is not None else None
            port = sock[1] if sock else 0
            token = request.query.get("token")
            auth = request.headers.get("Authorization", "")
            if token is None and auth.lower().startswith("token "):
                token = auth[6:].strip()
            why = self.refusal(request.path, request.headers.get("Host"), request.headers.get("Origin"), token,
                               port, request.path == "/socket")
            if why is not None:
                peer = request.remote or "?"
                self.log(f"oclgi view: refused {request.method} {request.path} from {peer}: {why}")
                return web.Response(status=403, text=f"oclgi view: refused: {why}\n")
            return await handler(request)

        return guard


def check_origins(values) -> list[str]:
    """--allow-origin values as origins; an OclgiError names one that is not."""
    from ..errors import OclgiError

    out = []
    for v in values or ():
        o = origin_of(v)
        if o is None:
            raise OclgiError(f"--allow-origin {v!r}: expected an origin such as http://192.168.1.5:8765 "
                             "(scheme, host and port; no path)")
        out.append(o)
    return out

