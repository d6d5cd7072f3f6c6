"""Standard output that goes away: a closed pipe (``oclgi render ... | head -0``)
or a full device (``> /dev/full``).

The command prints its "wrote FILE" lines after the files are in place, so
neither case loses any work; what is left to decide is how the command ends:

* a closed pipe: quietly, with status 141 (128 + SIGPIPE), what a program
  that the shell sees killed by SIGPIPE reports, as ``yes | head`` does;
* a full device (ENOSPC) or another write error: one line on stderr naming
  standard output and the problem, status 2 (an environment error, as every
  OclgiError).

Either way standard output is pointed at the null device afterwards, so that
Python's own flush at exit does not fail a second time with a traceback.
"""

from __future__ import annotations

import errno
import os
import sys
from contextlib import contextmanager

BROKEN_PIPE_STATUS = 141
WRITE_ERROR_STATUS = 2


def reopen_closed_stderr() -> None:
    """A command started with stderr closed (``2>&-``) runs as with
    ``2>/dev/null``: its messages go nowhere, its status and outputs are as
    ever. File descriptor 2 is pointed at the null device first, so that no
    file the command opens takes that number (a compiler's diagnostics,
    written to descriptor 2, would land in it), and ``sys.stderr`` (None
    then) becomes a stream on it."""
    try:
        os.fstat(2)
    except OSError:
        null = os.open(os.devnull, os.O_WRONLY)
        if null != 2:
            os.dup2(null, 2)
            os.close(null)
    if sys.stderr is None:
        sys.stderr = open(2, "w", closefd=False)  # noqa: SIM115 (the process' own stream, never closed)


class StdoutError(Exception):
    """Writing to standard output failed; ``error`` is the OSError. A type of
    its own, so that main tells it from any other OSError (an output file's
    are OclgiErrors naming the file)."""

    def __init__(self, error: OSError):
        super().__init__(str(error))
        self.error = error


class _Guarded:
    """sys.stdout, with its write errors raised as StdoutError."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except OSError as exc:
            raise StdoutError(exc) from None

    def flush(self):
        try:
            self._stream.flush()
        except OSError as exc:
            raise StdoutError(exc) from None

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextmanager
def guarded_stdout():
    """Within: writes to sys.stdout raise StdoutError; what was printed is
    flushed on the way out, whichever way (when a failure can still be
    reported, not at exit)."""
    stream = sys.stdout
    if stream is None:
        yield
        return
    sys.stdout = _Guarded(stream)
    try:
        yield
    finally:
        try:
            sys.stdout.flush()  # also after argparse's SystemExit (--help)
        finally:
            sys.stdout = stream


def _detach_stdout() -> None:
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        # No descriptor behind sys.stdout (an embedding application's stream):
        # drop what is buffered instead.
        sys.stdout = open(os.devnull, "w")


def stdout_failed(exc: StdoutError) -> int:
    """The exit status after ``exc`` (see the module's doc)."""
    error = exc.error
    _detach_stdout()
    if isinstance(error, BrokenPipeError) or error.errno == errno.EPIPE:
        return BROKEN_PIPE_STATUS
    reason = os.strerror(error.errno) if error.errno else str(error)
    print(f"oclgi: error: cannot write to standard output: {reason}", file=sys.stderr)
    return WRITE_ERROR_STATUS
