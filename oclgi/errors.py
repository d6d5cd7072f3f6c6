"""User-facing errors.

`OclgiError` carries a message meant for the user (bad scene, bad points, no
OpenCL device). The command line prints it as one line and exits with status 2;
library users catch it like any exception. Anything else is a bug and keeps its
traceback.
"""


class OclgiError(Exception):
    """An error caused by the input or the environment, with a clear message."""

    exit_code = 2


class OclgiWarning(UserWarning):
    """Something in the input was fixed up (e.g. degenerate triangles dropped)."""
