"""Parameters of a run, read and checked in one place for the command line,
the scene file and the Python API, with one set of messages.

Each reader takes the value as given (a Python number, a TOML value or a
command-line string already converted) and the name to report, and returns
the value in the type the engine uses or raises OclgiError.
"""

from __future__ import annotations

from .errors import OclgiError

# The estimator names; oclgi/estimators/__init__.py maps each to its class
# (and checks that the two lists agree). Kept here so that the scene layer
# can check a method name without importing the estimators.
METHODS = ("detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache", "impact", "photon_map")


def check_method(method) -> str:
    if method not in METHODS:
        raise OclgiError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return method
