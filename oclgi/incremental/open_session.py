"""The session a method needs (oclgi/incremental/protocol.py)."""

from __future__ import annotations

from .photon_map_session import PhotonMapSession
from .session import Session


def open_session(engine, points=None, method: str | None = None, **kwargs):
    """A session for ``method`` (the scene's or the default when None):
    ``PhotonMapSession`` for ``photon_map``, else ``Session``; the other
    arguments as theirs."""
    method = engine.run_params(method).method
    if method == "photon_map":
        return PhotonMapSession(engine, points, **kwargs)
    return Session(engine, points, method=method, **kwargs)
