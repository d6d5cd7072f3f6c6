"""Ctrl-C on the command line: one line, ``oclgi: interrupted``, and exit
status 130 (128 + SIGINT, what shells report for a job stopped by Ctrl-C),
whenever it comes: while Python imports numpy and pyopencl, while PoCL
compiles a kernel, during a run, and when it comes twice.

Standard library only: the command line imports this before anything slow.
"""

from __future__ import annotations

import os
import signal
import sys
from contextlib import contextmanager

EXIT_STATUS = 130
MESSAGE = "oclgi: interrupted"


def say_interrupted() -> None:
    """The one line on stderr (straight to file descriptor 2 if sys.stderr
    cannot take it)."""
    if sys.stderr is not None:
        try:
            print(MESSAGE, file=sys.stderr, flush=True)
            return
        except (OSError, ValueError):
            pass
    try:
        os.write(2, (MESSAGE + "\n").encode())
    except OSError:
        pass


def exit_interrupted():
    """Leave now, as interrupted (raises SystemExit, which prints nothing)."""
    ignore_further()
    say_interrupted()
    raise SystemExit(EXIT_STATUS)


def ignore_further() -> None:
    """A second Ctrl-C while the first unwinds (temporary files being removed,
    the device released) would raise in the middle of that clean-up and end
    with a traceback: from the first one on, further ones are ignored. The
    unwinding is short, as kernels run in short slices (cl/programs.launch)."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: nothing to change there
        pass


# A Ctrl-C came (the handler below ran). Some libraries swallow the
# KeyboardInterrupt it raises: trimesh wraps any exception raised while it
# imports an optional dependency (scipy, say), KeyboardInterrupt included,
# and goes on with a stand-in, so a Ctrl-C in those half-seconds was lost.
_pending = False


def _on_sigint(signum, frame):
    global _pending
    _pending = True
    ignore_further()
    raise KeyboardInterrupt


def reraise_swallowed() -> None:
    """Raise KeyboardInterrupt again if a Ctrl-C came and a library swallowed
    it (called after such imports, and between a run's batches)."""
    if _pending:
        raise KeyboardInterrupt


def keep_ignored() -> bool:
    """A job started with SIGINT ignored (``nohup``, ``cmd &`` in a script)
    must not be stopped by one. PoCL's compiler (LLVM) installs its own
    SIGINT handler during a kernel build, whatever the disposition was, and a
    SIGINT then aborts the build. Blocked in this thread before any other
    thread exists (numpy's, PoCL's), SIGINT is blocked in every thread the
    process will have, so no handler ever runs; an ignored signal is never
    wanted, so blocking it loses nothing. True if SIGINT was ignored."""
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        return False
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    return True


@contextmanager
def handled(command_line: bool = True):
    """Within: the first Ctrl-C raises KeyboardInterrupt (which the command's
    main turns into the one line and 130) and the next ones are ignored; a
    SIGINT ignored at start stays ignored.

    On the way out of a ``command_line`` run the process is about to end:
    SIGINT is ignored from then on, as Python's teardown (releasing the
    device, PoCL's threads) would otherwise meet it with the default action
    and die of it, after the work was done. For a caller that goes on
    (``command_line`` False: main called in-process) the previous handler
    comes back, unless a Ctrl-C came."""
    if keep_ignored():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    except KeyboardInterrupt:
        raise
    except BaseException:
        _leave(command_line, previous)
        raise
    _leave(command_line, previous)


def _leave(command_line: bool, previous) -> None:
    if command_line:
        ignore_further()
    else:
        signal.signal(signal.SIGINT, previous)
