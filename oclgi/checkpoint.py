"""Checkpoints of a run: saved atomically, checked before they are resumed.

A checkpoint is a ``.npz`` file (no pickles) holding a run's state
(oclgi/tracing/run.py ``RunState``: the next path, the segments traced and
the estimator's sums) and what the state is the state *of*:

- ``scene``: the compiled scene's fingerprint (its tree, triangles, poses,
  materials and emitters as the device holds them; ``CompiledScene.fingerprint``);
- ``points``: a hash of the query points (for a render: the camera, its
  size and what the camera sees);
- ``params``: the run's parameters and the estimator's options;
- ``version``: oclgi's version and the file format's;
- ``command``: the command line's own settings (image size, samples,
  outputs, ...; oclgi/resumable.py), which ``--resume`` takes where the
  command line names none.

Resuming from a checkpoint whose record differs from the resumed run's is
refused with what differs (exit status 2 on the command line), never run:
its sums would silently be of another run. The device's name is recorded
too; another device resumes with a warning (equal bits are promised on one
device, not across devices).

:class:`Saver` writes one every ``every`` seconds of work and when told to;
:func:`deferred_stop` turns Ctrl-C and SIGTERM into a request that the run
loop honours between batches, so that the state saved is a whole batch's.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import signal
import threading
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import OclgiError

FORMAT = 1
SUFFIX = ".npz"
META_KEY = "meta"
SUMS_PREFIX = "sums."
DEFAULT_EVERY = 10.0  # seconds of work between saves


def points_hash(points) -> str:
    h = hashlib.sha256()
    for a in (points.positions, points.normals, points.barys):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _jsonable(value):
    for kind, plain in ((np.integer, int), (np.floating, float), (np.bool_, bool), (Path, str)):
        if isinstance(value, kind):
            return plain(value)
    return value


def record(run, options: dict | None = None) -> dict:
    """What the run's state is the state of (module docstring)."""
    from . import __version__

    p = dataclasses.asdict(run.params)
    return {
        "format": FORMAT,
        "version": __version__,
        "scene": run.engine.compiled.fingerprint(),
        "scene_name": run.engine.scene.name,
        "points": points_hash(run.estimator.points),
        "n_points": int(run.estimator.n),
        "params": {k: _jsonable(v) for k, v in p.items()},
        "options": {k: _jsonable(v) for k, v in sorted((options or {}).items())},
        "device": run.engine.queue.device.name.strip(),
    }


def save(path: Path, run, options: dict | None = None, command: dict | None = None) -> None:
    """Write the run's state to ``path`` atomically (whole or not at all);
    ``command``: the command line's settings to keep with it (JSON values)."""
    from .io import atomic_path

    state = run.state()
    meta = record(run, options)
    if command:
        meta["command"] = command
    meta.update(first=state.paths.first, count=state.paths.count, next_path=state.next_path,
                segments=state.segments)
    arrays = {SUMS_PREFIX + k: v for k, v in state.sums.items()}
    arrays[META_KEY] = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), np.uint8)
    with atomic_path(Path(path)) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)


def _read(path: Path, sums: bool) -> tuple:
    """(record, sums or None) of the checkpoint file at ``path``, refused as one line."""
    path = Path(path)
    if not path.is_file():
        raise OclgiError(f"{path}: no such checkpoint file")
    try:
        with np.load(path, allow_pickle=False) as z:
            files = set(z.files)
            if META_KEY not in files:
                raise ValueError("no record")
            meta = json.loads(bytes(z[META_KEY]).decode())
            arrays = {k[len(SUMS_PREFIX):]: z[k] for k in files if k.startswith(SUMS_PREFIX)} if sums else None
    except Exception as exc:  # noqa: BLE001 - whatever a damaged or crafted file raises (a record nested
        # 10^5 deep: RecursionError; a member declaring 10^20 elements: OverflowError) is one refusal
        raise OclgiError(f"{path}: not an oclgi checkpoint ({type(exc).__name__}: {_short(exc)})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise OclgiError(f"{path}: not an oclgi checkpoint of format {FORMAT}")
    return meta, arrays


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 160 else text[:157] + "..."


def read_record(path: Path) -> dict:
    """The record of the checkpoint at ``path``, without its sums."""
    return _read(path, sums=False)[0]


def load(path: Path) -> tuple:
    """The record and the state of the checkpoint at ``path``."""
    from .tracing.run import PathRange, RunState  # pyopencl: not at the command line's start

    meta, sums = _read(path, sums=True)
    try:
        paths = PathRange(int(meta["first"]), int(meta["count"]))
        state = RunState(paths, int(meta["next_path"]), int(meta["segments"]), sums)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise OclgiError(f"{path}: a damaged oclgi checkpoint ({type(exc).__name__}: {_short(exc)})") from None
    return meta, state


def check(path: Path, saved: dict, current: dict, photons_may_grow: bool = False) -> None:
    """Refuse ``saved`` (a checkpoint's record) unless it is of the run
    ``current`` describes. ``photons_may_grow``: the run adds photons
    (``--more``), so its count may be above the saved one."""
    problems = []
    if saved.get("version") != current["version"]:
        problems.append(f"it was written by oclgi {saved.get('version')}, this is {current['version']}")
    if saved.get("scene") != current["scene"]:
        problems.append(f"its scene differs from {current['scene_name']!r} (geometry, poses, materials or "
                        "lights, or the tree builder)")
    if saved.get("points") != current["points"] or saved.get("n_points") != current["n_points"]:
        problems.append("its query points differ (another points file, camera or image size)")
    sp, cp = dict(saved.get("params") or {}), dict(current["params"])
    if photons_may_grow:
        sp.pop("photons", None)
        cp.pop("photons", None)
    for key in sorted(set(sp) | set(cp)):
        if sp.get(key) != cp.get(key):
            problems.append(f"its {key} is {sp.get(key)!r}, this run's {cp.get(key)!r}")
    if (saved.get("options") or {}) != current["options"]:
        problems.append(f"its estimator options are {saved.get('options')}, this run's {current['options']}")
    if problems:
        raise OclgiError(f"{path} is the checkpoint of another run: " + "; ".join(problems))
    if saved.get("device") != current["device"]:
        from .scene.scene import OclgiWarning

        warnings.warn(f"{path} was written on {saved.get('device')!r}, resumed on {current['device']!r}: "
                      "equal results are promised on one device only", OclgiWarning, stacklevel=2)


@contextmanager
def exclusive(path: Path, fresh: bool):
    """Within: this process alone writes the checkpoint at ``path``; another
    run that names it is refused at once (two runs saving into one file
    would silently replace each other's state). ``fresh``: a new run, which
    is refused if the file exists by the time it holds it.

    The lock is an advisory lock (flock) on a hidden file beside it, which
    the kernel drops when its process ends, however it ends: a run killed
    by SIGKILL leaves no stale lock, only the empty file, which the next
    run reuses and removes."""
    import fcntl
    import os

    path = Path(path)
    lock = path.parent / f".{path.name}.oclgi-lock"
    while True:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)  # as the first save would
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OclgiError(f"cannot lock the checkpoint {path}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise OclgiError(f"{path} is the checkpoint of another oclgi run going on now: wait for it to end, "
                             "or give this run another --checkpoint file") from None
        try:  # the file locked must still be the one named (its last holder may have removed it)
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        if fresh and path.exists():
            raise OclgiError(f"{path} exists: continue its run with --resume {path}, or remove it")
        yield
    finally:
        try:
            os.unlink(lock)
        except OSError:
            pass
        os.close(fd)


class Saver:
    """Saves a run to ``path`` every ``every`` seconds of work (``on_batch``
    is the run loop's hook) and on request (``save``)."""

    def __init__(self, path: Path, options: dict | None = None, every: float = DEFAULT_EVERY,
                 command: dict | None = None):
        self.path, self.options, self.command, self.every = Path(path), options, command, float(every)
        self.last = time.monotonic()

    def save(self, run) -> None:
        save(self.path, run, self.options, self.command)
        self.last = time.monotonic()

    def on_batch(self, run) -> None:
        if time.monotonic() - self.last >= self.every:
            self.save(run)


class StopRequested(Exception):
    """Ctrl-C or SIGTERM came during a run with a checkpoint: the loop has
    saved its state after the batch in flight, and the command ends."""

    def __init__(self, signum: int, path: Path | None = None):
        super().__init__(signal.Signals(signum).name)
        self.signum, self.path = signum, path


class _Stop:
    def __init__(self):
        self.signum = None

    def __call__(self, signum, frame):
        if self.signum is not None:  # a second one: stop now, the last save stands
            raise KeyboardInterrupt
        self.signum = signum


@contextmanager
def deferred_stop():
    """Within: SIGINT and SIGTERM only set ``stop.signum`` (the yielded
    object); the run loop checks it between batches. A second signal raises
    KeyboardInterrupt at once. Outside the main thread nothing changes."""
    stop = _Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        current = signal.getsignal(signum)
        if current == signal.SIG_IGN:
            continue
        previous[signum] = current
        signal.signal(signum, stop)
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
