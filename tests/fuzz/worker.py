"""The fuzz worker: runs cases in-process, one request per line on stdin.

Each request is a JSON line ``{"dir": FOLDER, "argv": [...]}`` (the command
line, as ``oclgi.cli.main`` takes it, run with FOLDER as the working folder)
or ``{"dir": FOLDER, "desc": BASE64}`` (a pickled scene dict for
``oclgi.load_dict``, with FOLDER as its base folder). The answer is one JSON
line ``{"rc", "stdout", "stderr", "traceback"}`` on the stdout the worker
started with; the worker's own file descriptors 1 and 2 are redirected, so
that nothing the engine's C libraries print can garble the answers, and
what they print on 2 is still part of the case's stderr.

A case that kills the worker (a signal) or never answers is the parent's to
report (:class:`fuzz.oracle.Worker`); this process only runs one case after
another, importing oclgi and compiling its kernels once.
"""

import base64
import contextlib
import io
import json
import os
import pickle
import sys
import tempfile
import traceback
import warnings


def _run(request) -> dict:
    out, err = io.StringIO(), io.StringIO()
    tb = None
    rc = None
    with tempfile.TemporaryFile() as native_err:
        saved = os.dup(2)
        os.dup2(native_err.fileno(), 2)
        try:
            os.chdir(request["dir"])
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                rc = _call(request)
        except BaseException:  # what escapes the command line is the finding
            tb = traceback.format_exc()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            os.chdir(os.path.dirname(request["dir"]))
        native_err.seek(0)
        native = native_err.read().decode("utf-8", "replace")
    return {"rc": rc, "stdout": out.getvalue(), "stderr": err.getvalue() + native, "traceback": tb}


def _call(request):
    if "argv" in request:
        from oclgi.cli import main

        try:
            return main(request["argv"])
        except SystemExit as exc:  # argparse's errors and --help
            return exc.code if isinstance(exc.code, int) else 1
    from oclgi import OclgiError, load_dict

    desc = pickle.loads(base64.b64decode(request["desc"]))
    # the API warns through the warnings module: shown as the command line shows them
    # and the error folded on one line as the command line folds it: an API
    # message may hold a value's repr over several lines
    from oclgi.cli import _one_line

    error = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            load_dict(desc, base_dir=request["dir"])
        except OclgiError as exc:
            error = exc
    for w in caught:
        print(f"oclgi: warning: {_one_line(w.message)}", file=sys.stderr)
    if error is not None:
        print(f"oclgi: error: {_one_line(error)}", file=sys.stderr)
        return 2
    return 0


def main():
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    quiet = os.open(os.devnull, os.O_WRONLY)
    os.dup2(quiet, 1)
    import oclgi.cli  # noqa: F401  (imported once, before the first case's clock starts)

    answers.write("ready\n")
    for line in sys.stdin:
        answers.write(json.dumps(_run(json.loads(line))) + "\n")


if __name__ == "__main__":
    main()
