"""Running the ``oclgi`` command the way a user does, in a subprocess, or
in-process (quicker: one import, one kernel cache) through ``oclgi.cli.main``."""

import subprocess
import sys


def run(cwd, *args, env=None, timeout=300):
    """``python -m oclgi *args`` in ``cwd`` (None: here), in the environment
    ``env`` (None: this one); text output captured."""
    return subprocess.run([sys.executable, "-m", "oclgi", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def in_process(monkeypatch, capsys, cwd, *args):
    """``oclgi.cli.main(args)`` in ``cwd``, as a CompletedProcess (stdout and
    stderr as captured by pytest's ``capsys``)."""
    from oclgi.cli import main

    monkeypatch.chdir(cwd)
    capsys.readouterr()
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:  # argparse
        rc = exc.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(args, rc, out, err)


def entries_under(d):
    """Every file and folder under ``d``."""
    return {p.relative_to(d) for p in d.rglob("*")}


def fails_cleanly(runner, cwd, *args, match=None, alone=False):
    """``runner(cwd, *args)`` (``run``, or ``in_process`` with its fixtures
    bound) fails cleanly: exit status 2, stderr's last line ``oclgi: error:
    ...`` (matching the regex ``match``, if given) after warning lines only
    (none with ``alone``), no traceback, nothing on stdout, no file or folder
    made or removed under ``cwd``. Returns the error line."""
    import re

    before = entries_under(cwd)
    res = runner(cwd, *args)
    lines = res.stderr.splitlines()
    assert "Traceback" not in res.stderr, res.stderr
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert lines and lines[-1].startswith("oclgi: error: "), res.stderr
    assert all(line.startswith("oclgi: warning: ") for line in lines[:-1]), res.stderr
    assert not alone or len(lines) == 1, res.stderr
    assert res.stdout == "", res.stdout
    assert entries_under(cwd) == before, "files were left behind"
    if match is not None:
        assert re.search(match, lines[-1]), lines[-1]
    return lines[-1]
