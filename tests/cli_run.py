"""Running the ``oclgi`` command the way a user does, in a subprocess."""

import subprocess
import sys


def run(cwd, *args):
    """``python -m oclgi *args`` in ``cwd`` (None: here); text output captured."""
    return subprocess.run([sys.executable, "-m", "oclgi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)
