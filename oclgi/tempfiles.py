"""The temporary files (and folders) oclgi's writers stage their outputs in.

Each is named beside its target, recognisably as oclgi's and with the
process that owns it: ``.NAME.oclgi-tmp-PID-RANDOM.ext``. The live ones are
kept in a registry so that SIGTERM (and SIGHUP) can remove them before the
process ends; one that SIGKILL left behind is removed by the next oclgi write
into that folder, once its PID is no longer alive. Nothing that does not
match the pattern is ever removed.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import signal
import threading
from pathlib import Path

# The letters of the random part: what secrets.token_hex gives.
_PATTERN = re.compile(r"^\..*\.oclgi-tmp-(\d+)-[0-9a-f]{8}(\.[^.]*)?$")

_live: set[Path] = set()
_cleaned: set[Path] = set()  # folders already swept of stale files by this process
_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
_previous: dict = {}


def _name(path: Path, suffix: str) -> Path:
    # The target's suffix is kept: OpenImageIO picks the format by it.
    return path.parent / f".{path.stem}.oclgi-tmp-{os.getpid()}-{secrets.token_hex(4)}{suffix}"


def is_temporary(name: str) -> bool:
    """Whether ``name`` is one of oclgi's temporary names."""
    return _PATTERN.match(name) is not None


def create_file(path: Path, suffix: str | None = None) -> Path:
    """A new empty temporary file beside ``path``, registered as live.

    Created with mode 0666 less the umask, as a plain ``open`` would, so the
    renamed output gets the usual permissions (mkstemp's would be 0600).
    """
    while True:
        tmp = _name(path, path.suffix if suffix is None else suffix)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        _live.add(tmp)
        os.close(fd)
        return tmp


def create_folder(path: Path) -> Path:
    """A new empty temporary folder beside ``path``, registered as live."""
    while True:
        tmp = _name(path, "")
        try:
            os.mkdir(tmp)
        except FileExistsError:
            continue
        _live.add(tmp)
        return tmp


def release(tmp: Path) -> None:
    """``tmp`` was renamed into place (or removed): no longer ours to clean."""
    _live.discard(tmp)


def remove(tmp: Path) -> None:
    """Remove a temporary file or folder (what is already gone is fine)."""
    try:
        if tmp.is_dir() and not tmp.is_symlink():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
    except OSError:
        pass  # removing is best effort: the next run's sweep tries again
    release(tmp)


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process: alive
    except OverflowError:
        return False  # no process has such a number
    return True


def remove_stale(folder: Path) -> None:
    """Remove oclgi's temporary files in ``folder`` whose process has ended
    (a run killed by SIGKILL or a power loss); once per folder and process."""
    folder = Path(folder)
    key = folder.resolve()
    if key in _cleaned:
        return
    _cleaned.add(key)
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        m = _PATTERN.match(entry.name)
        if m and not _alive(int(m.group(1))):
            remove(Path(entry.path))


def _on_signal(signum, frame):
    previous = _previous.get(signum)
    if callable(previous):
        # Someone else handles it (e.g. by raising, which unwinds through the
        # writers' own clean-up): leave the files to them.
        return previous(signum, frame)
    for tmp in list(_live):
        remove(tmp)
    # Then end as the signal would have ended us, status and all.
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)


def install_signal_cleanup() -> None:
    """Remove the live temporary files on SIGTERM and SIGHUP, then end as the
    signal would have. A handler already installed is called instead (it is
    chained, not replaced); an ignored signal stays ignored. Only the main
    thread can install handlers: elsewhere this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in _SIGNALS:
        current = signal.getsignal(signum)
        if current is _on_signal or current == signal.SIG_IGN:
            continue
        _previous[signum] = current
        signal.signal(signum, _on_signal)
