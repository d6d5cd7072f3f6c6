"""A scene file's values, read and checked: keys, vectors, radiant values, numbers.

Shared by the scene description (oclgi/scene/description.py) and the
lights' tables (oclgi/scene/light_tables.py): every error is one line
naming the key (``where``), and unknown keys are errors.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..errors import OclgiError

# The device holds emission and intensity in float32: a positive value
# outside its normal range would round to 0 or inf, and so would the
# photons' power (a division by zero, or NaN everywhere).
F32_TINY = float(np.finfo(np.float32).tiny)  # 1.2e-38
F32_MAX = float(np.finfo(np.float32).max)  # 3.4e38


def check_keys(d, allowed, where):
    if not isinstance(d, dict):
        raise OclgiError(f"{where}: expected a table, got {type(d).__name__}")
    not_names = [k for k in d if not isinstance(k, str)]
    if not_names:  # a dict made in Python may have any keys; TOML's are names
        raise OclgiError(f"{where}: keys must be names (strings), got {_show_key(not_names[0])}")
    unknown = set(d) - allowed
    if unknown:
        raise OclgiError(f"{where}: unknown key(s) {sorted(unknown)} (allowed: {sorted(allowed)})")


def _show_key(key) -> str:
    text = repr(key)
    return text if len(text) <= 40 else text[:37] + "..."


def _show(x: float) -> str:
    return f"{x:.2g}".replace("e+", "e")


def vec3(value, where, limit=F32_MAX):
    """3 finite numbers, none beyond ``limit`` in size (by default float32's
    range: the device would see infinity)."""
    if isinstance(value, (str, bytes, dict)) or value is None:
        raise OclgiError(f"{where}: expected 3 numbers, got {value!r}")
    try:
        if any(isinstance(x, bool) for x in value):
            raise TypeError
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer beyond float's range
        raise OclgiError(f"{where}: expected 3 numbers, got {value!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise OclgiError(f"{where}: expected 3 finite numbers, got {value!r}")
    if any(abs(x) > limit for x in v):
        why = ("float32 on the device" if limit == F32_MAX
               else "as for vertex coordinates: the device squares them in float32")
        raise OclgiError(f"{where}: expected 3 numbers, each from -{_show(limit)} to {_show(limit)} ({why}), "
                         f"got {value!r}")
    return v


def radiant(value, where):
    """An emission or intensity: 3 numbers, each 0 or in float32's normal
    range (negative ones are the scene's to refuse, with the material's name)."""
    v = vec3(value, where, math.inf)
    if any(0 < x < F32_TINY or x > F32_MAX for x in v):
        raise OclgiError(f"{where}: expected 3 numbers, each 0 or from 1.2e-38 to 3.4e38 "
                         f"(float32 on the device), got {value!r}")
    return v


def number(value, where, kind=float):
    """A finite number within float32's range (the device's), as ``kind``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise OclgiError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise OclgiError(f"{where}: expected a finite number, got {value!r}")
    if abs(value) > F32_MAX:  # an int is compared exactly: no float conversion to overflow
        raise OclgiError(f"{where}: expected a number from -3.4e38 to 3.4e38 (float32 on the device), "
                         f"got {value!r}")
    if kind is int:
        if float(value) != int(value):
            raise OclgiError(f"{where}: expected an integer, got {value!r}")
        return int(value)
    return float(value)


def file_path(value, where: str, what: str, base_dir=None) -> Path:
    """The file ``value`` names (a string or a path-like), relative to ``base_dir``."""
    given = os.fspath(value) if isinstance(value, os.PathLike) else value
    if not isinstance(given, str) or not given.strip():
        raise OclgiError(f"{where}: expected {what}, got {value!r}")
    path = Path(given)
    return path if path.is_absolute() or base_dir is None else Path(base_dir) / path


def table_list(value, name):
    """``[[name]]`` (a list of tables) or a single ``[name]`` table, as a list."""
    if isinstance(value, dict):
        return [value]
    if not isinstance(value, list):
        raise OclgiError(f"{name}: expected [[{name}]] tables, got {value!r}")
    return value
