"""One memory budget for every page of ``oclgi view``.

Each page's session holds its stored paths (about ``photons x max_depth x
48`` bytes: 4,000,000 photons take 3 GiB), and a render holds its image's
points for as long as it runs; nothing bounded them across pages, and a few
pages asking the per-page maximum took a 23 GiB machine past 22 GiB. The
ledger books what each page holds (oclgi/budget.py's estimates) against one
limit for the whole server: by default half of the device's memory and half
of the machine's (one pool on a CPU device, whose buffers are the
machine's memory), ``--memory`` to set it. A request that would pass it is
refused before any work, with a message naming the limit; the page keeps
its session as it was. ``--max-pages`` bounds the pages open at once.
"""

from __future__ import annotations

import threading

from .. import budget
from ..errors import OclgiError

DEFAULT_MAX_PAGES = 8
SESSION_HOST_BYTES = 64 << 20  # a session's host side: its tables, points and frames, about


def machine_memory() -> int:
    """The machine's memory in bytes (Linux's MemTotal), 0 where unknown."""
    return budget.meminfo("MemTotal") or 0


def session_bytes(photons: int, max_depth: int, n_points: int) -> int:
    """What a page's session holds, about: its path-major store of every
    segment slot, its points' buffers and its host side."""
    return int(photons) * int(max_depth) * budget.SEGMENT_BYTES + int(n_points) * budget.POINT_HOST_BYTES \
        + SESSION_HOST_BYTES


class Ledger:
    """The bytes each page holds (``key`` -> bytes), against ``limit``."""

    def __init__(self, limit: int, max_pages: int = DEFAULT_MAX_PAGES):
        if not limit > 0:
            raise OclgiError(f"--memory must be a positive size, got {limit!r}")
        self.limit, self.max_pages = int(limit), int(max_pages)
        self.held: dict = {}
        self.lock = threading.Lock()  # the device's thread books renders, the event loop sessions

    @classmethod
    def for_device(cls, device, memory: int | None = None, max_pages: int = DEFAULT_MAX_PAGES) -> "Ledger":
        """Half of the device's memory and half of the machine's by default
        (the smaller of the two on a CPU device, whose buffers are the
        machine's memory)."""
        if memory is None:
            halves = [m // 2 for m in (int(device.global_mem_size), machine_memory()) if m > 0]
            memory = min(halves)
        return cls(memory, max_pages)

    @property
    def used(self) -> int:
        return sum(self.held.values())

    def book(self, key, nbytes: int, what: str) -> None:
        """Hold ``nbytes`` for ``key`` (replacing what it held), or refuse
        with the limit named; nothing changes on a refusal."""
        with self.lock:
            others = self.used - self.held.get(key, 0)
            if others + nbytes > self.limit:
                raise OclgiError(
                    f"{what} needs about {budget.gib(nbytes)}, and the server's memory budget of "
                    f"{budget.gib(self.limit)} (--memory) has {budget.gib(max(self.limit - others, 0))} left "
                    f"with the other pages' sessions and renders: ask for fewer photons or a smaller image, "
                    f"or close other pages")
            self.held[key] = int(nbytes)

    def release(self, key) -> None:
        with self.lock:
            self.held.pop(key, None)

    def release_page(self, page) -> None:
        """All a page held: its session, and its render or second session under way."""
        with self.lock:
            for key in [k for k in self.held if k is page or (isinstance(k, tuple) and k[0] is page)]:
                del self.held[key]

    def check_page(self, open_pages: int) -> None:
        if open_pages >= self.max_pages:
            raise OclgiError(f"the server serves at most {self.max_pages} pages at once (--max-pages): close "
                             "another page first")


def parse_size(text: str) -> int:
    """``--memory``: bytes, or a number with K, M, G or T (binary units, optionally followed by iB or B)."""
    t = str(text).strip().upper().replace(" ", "")
    for suffix in ("IB", "B"):
        if t.endswith(suffix) and len(t) > len(suffix) and t[-len(suffix) - 1] in "KMGT":
            t = t[:-len(suffix)]
            break
    scale = 1
    if t and t[-1] in "KMGT":
        scale, t = 1 << (10 * ("KMGT".index(t[-1]) + 1)), t[:-1]
    try:
        value = float(t) * scale
    except ValueError:
        value = float("nan")
    if not (value >= 1 << 20 and value < float(1 << 60)):
        raise OclgiError(f"--memory: expected a size such as 8G or 512M (at least 1M), got {text!r}")
    return int(value)
