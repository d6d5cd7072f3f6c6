"""Parameters of a run, read and checked in one place for the command line,
the scene file and the Python API, with one set of messages.

Each reader takes the value as given (a Python number, a TOML value, or a
command-line word that :func:`number_text` has turned into a number where it
could) and the name to report, the caller's: ``--photons`` on the command
line, ``photons.count`` in a scene file, ``photons`` in the API. It returns
the value in the type the engine uses, or raises :class:`ParamError`, whose
message is ``NAME: PROBLEM`` with one PROBLEM per parameter whichever way the
value came in (the command line prints it after argparse's ``argument NAME:``).

>>> photons(1e5)
100000
>>> photons(2.5, "photons.count")
Traceback (most recent call last):
...
oclgi.params.ParamError: photons.count: expected a positive integer up to 2^31, got 2.5
>>> RunParams(method="impact", photons=2e3).photons
2000
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .errors import OclgiError

# The estimator names; oclgi/estimators/__init__.py maps each to its class
# (and checks that the two lists agree). Kept here so that the scene layer
# can check a method name without importing the estimators.
METHODS = ("detp", "detp_disc_index", "detp_ray_map", "detp_sphere_cache", "impact", "photon_map", "ray_map_knn")

MAX_PHOTONS = 1 << 31
MAX_DEPTH_LIMIT = 256  # keeps fixed-point sums of 10^9 photons below 2^63
# Lengths the device squares in float32 (the DETP disc's d^2): from 1e-18 to
# 1e18 their squares stay normal float32 numbers (1.2e-38 .. 3.4e38) with
# room to spare, as vertex coordinates do (scene.MAX_COORDINATE).
MIN_RADIUS = 1e-18
MAX_LENGTH = 1e18

F32_MAX = float(np.finfo(np.float32).max)  # 3.4e38
F32_TINY = float(np.finfo(np.float32).tiny)  # 1.2e-38, the smallest normal float32
MAX_IMAGE_SIDE = 16384  # pixels, as a scene's camera allows
MAX_FRAMES = 1_000_000
MAX_SEEDS = 1 << 40  # the study's seeds are below its reference's (oclgi/study/reference.py)

# The run parameters, in RunParams' order.
RUN_KEYS = ("method", "photons", "radius", "seed", "max_depth", "extension", "count_emitted")
# Run parameters that may come among a method's options (``-O extension=0.1``,
# ``Config(..., count_emitted=False)``): the estimators take them as keyword
# arguments, and the command line has no flag of their own for them.
OPTION_PARAMS = ("extension", "count_emitted")
# What the engine hands every estimator itself: never an option.
ENGINE_ARGS = frozenset({"self", "queue", "compiled", "points", "local_size", "count_work", "pilot"})


class ParamError(OclgiError):
    """A bad parameter value: ``name: problem``."""

    def __init__(self, name: str, problem: str):
        super().__init__(f"{name}: {problem}")
        self.name, self.problem = name, problem


def _number(x: float) -> str:
    """A bound as messages write it: 1e18, not 1e+18."""
    return f"{x:g}".replace("e+", "e")


def _show(value) -> str:
    """The value as the message shows it (numpy scalars as plain numbers)."""
    if isinstance(value, np.generic):
        value = value.item()
    return repr(value)


def number_text(text: str):
    """A command-line word as an int, else a float, else the word itself
    (for the readers to refuse), so that ``--photons 1e5`` and ``count =
    1e5`` reach the reader as the same value."""
    text = text.strip()
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def integral(value) -> int | None:
    """``value`` as an int if it is an integer (an int, or a float with no
    fraction: ``1e5``); None otherwise. Never rounds; a bool is no integer."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
        return int(value)
    return None


def _real(value) -> float | None:
    """``value`` as a finite float if it is a number; None otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return None
    try:
        v = float(value)
    except OverflowError:  # an int beyond float's range
        return None
    return v if math.isfinite(v) else None


# -- one reader per parameter ---------------------------------------------------------


def method(value, name: str = "method") -> str:
    if not isinstance(value, str) or value not in METHODS:
        raise ParamError(name, f"unknown method {_show(value)}; choose one of {', '.join(METHODS)}")
    return value


def _in_range(value, name: str, lo, hi, wanted: str, read=integral):
    """``value`` read as an int (or with ``_real``, a finite float) in lo..hi,
    else ParamError "expected WANTED"."""
    v = read(value)
    if v is None or not lo <= v <= hi:
        raise ParamError(name, f"expected {wanted}, got {_show(value)}")
    return v


def photons(value, name: str = "photons") -> int:
    return _in_range(value, name, 1, MAX_PHOTONS, "a positive integer up to 2^31")


def photon_counts(values, name: str = "photons") -> list:
    """One photon count or a sequence of them, as a list of ints."""
    if isinstance(values, (str, bytes)) or np.isscalar(values):
        items = [values]
    else:
        try:
            items = list(values)
        except TypeError:
            items = [values]
    counts = [integral(v) for v in items]
    if not counts or any(n is None or not 0 < n <= MAX_PHOTONS for n in counts):
        raise ParamError(name, f"expected photon counts (positive integers up to 2^31), got {_show(values)}")
    return counts


def seed(value, name: str = "seed") -> int:
    return _in_range(value, name, 0, 2**64 - 1, "an integer in 0..2^64-1")


MAX_SPP = 256


def samples_per_pixel(value, name: str = "spp") -> int:
    return _in_range(value, name, 1, MAX_SPP, f"an integer in 1..{MAX_SPP}")


def max_depth(value, name: str = "max_depth") -> int:
    return _in_range(value, name, 1, MAX_DEPTH_LIMIT, f"an integer in 1..{MAX_DEPTH_LIMIT}")


def radius(value, name: str = "radius") -> float:
    return _in_range(value, name, MIN_RADIUS, MAX_LENGTH, f"a number from {_number(MIN_RADIUS)} to "
                     f"{_number(MAX_LENGTH)} (the device squares it in float32)", _real)


def extension(value, name: str = "extension") -> float:
    return _in_range(value, name, 0.0, MAX_LENGTH, f"a number from 0 to {_number(MAX_LENGTH)}", _real)


def count_emitted(value, name: str = "count_emitted") -> bool:
    return flag(value, name)


# -- parameters of the API and the command line beyond a run's ---------------------------------


def flag(value, name: str) -> bool:
    """True or false, and nothing else (not 0, 1 or a word)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ParamError(name, f"expected true or false, got {_show(value)}")
    return bool(value)


def float32_real(value, name: str, lo: float | None = None, hi: float | None = None) -> float:
    """A finite number the device can hold in float32 without becoming inf
    or losing it to the subnormals: 0, or a magnitude from 1.2e-38 to
    3.4e38; within lo..hi when they are given (a scene file's values, and the
    API's, go through this where the device takes them as float32)."""
    r = _real(value)
    lo_ = -F32_MAX if lo is None else max(lo, -F32_MAX)
    hi_ = F32_MAX if hi is None else min(hi, F32_MAX)
    if r is None or not lo_ <= r <= hi_ or 0 < abs(r) < F32_TINY:
        short = lambda x: _number(x) if abs(x) < 1e6 else f"{x:.2g}".replace("e+", "e")
        span = f"from {short(lo_)} to {short(hi_)}"
        raise ParamError(name, f"expected a number {span}, 0 or at least 1.2e-38 in size "
                               f"(float32 on the device), got {_show(value)}")
    return r


AUTO = "auto"


def exposure(value, name: str = "exposure") -> float | str:
    """The tone mapping's multiplier (a float32 on the device), or "auto"
    (the image's own: ``oclgi.engine.auto_exposure``)."""
    if isinstance(value, str) and value.strip().lower() == AUTO:
        return AUTO
    r = _real(value)
    if r is None or not F32_TINY <= r <= F32_MAX:
        raise ParamError(name, f"expected 'auto' or a positive number from 1.2e-38 to 3.4e38 (float32 on the "
                               f"device), got {_show(value)}")
    return r


# The views from radiance to display pixels (kernels/view_transform.h);
# "srgb", the first, is the default: clamp and the sRGB encoding, as before.
VIEWS = ("srgb", "agx", "filmic")


def view(value, name: str = "view") -> str:
    """A view transform's name (VIEWS), case-insensitive."""
    if isinstance(value, str) and value.strip().lower() in VIEWS:
        return value.strip().lower()
    raise ParamError(name, f"expected one of {', '.join(VIEWS)}, got {_show(value)}")


def image_size(value, name: str = "width") -> int:
    """An image's width or height in pixels (the camera's limit, oclgi/scene/description.py)."""
    return _in_range(value, name, 1, MAX_IMAGE_SIDE, f"an integer in 1..{MAX_IMAGE_SIDE}")


def frames(value, name: str = "frames") -> int:
    """An animation's number of frames. Each frame is a move, a render and
    an image file: beyond MAX_FRAMES a run is no animation one could wait
    for (nor a folder one could list), and its poses alone would take
    gigabytes (oclgi.budget.frames says how many)."""
    return _in_range(value, name, 1, MAX_FRAMES, f"an integer in 1..{MAX_FRAMES:,}")


def seed_count(value, name: str = "seeds") -> int:
    """A study's number of seeds: at least 2 for a variance, at most one
    per seed of the study's range (oclgi/study/reference.py)."""
    return _in_range(value, name, 2, MAX_SEEDS, f"an integer from 2 (for a variance) to {MAX_SEEDS:,}")


def batch_bytes(value, name: str = "batch_bytes") -> int:
    """The bytes of one batch of traced segments (the engine's batching)."""
    return _in_range(value, name, 1 << 16, 1 << 40, "a number of bytes from 64 KiB to 1 TiB")


def local_size(value, name: str = "local_size") -> int:
    """A work-group size (the device's own limit is checked by the engine)."""
    return _in_range(value, name, 1, 2**31 - 1, "a positive integer")


READERS = {"method": method, "photons": photons, "radius": radius, "seed": seed, "max_depth": max_depth,
           "extension": extension, "count_emitted": count_emitted}


# -- a method's own options -------------------------------------------------------------


def option(key: str, value):
    """One ``key=value`` given among a method's options: a run parameter of
    OPTION_PARAMS is read as such, the other run parameters are refused (they
    have their own argument), a method's own option passes as it is."""
    if key in OPTION_PARAMS:
        return READERS[key](value, key)
    not_a_parameter(key)
    return value


def not_a_parameter(key: str) -> None:
    if key in RUN_KEYS or key in ENGINE_ARGS:
        raise OclgiError(f"{key} is a parameter of its own, not an option of a method")


def option_text(text: str) -> tuple:
    """``KEY=VALUE`` as the command line's ``-O`` gives it: the value read as
    an int, else a float, else true/false, else a string (then ``option``)."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise ParamError("-O", f"expected KEY=VALUE, got {text!r}")
    word = number_text(value)
    if isinstance(word, str) and word.lower() in ("true", "false"):
        word = word.lower() == "true"
    return key, option(key, word)


# -- the parameters of a run ---------------------------------------------------------------


@dataclass(frozen=True)
class RunParams:
    """The parameters of a run, checked when made (a bad one raises
    ParamError under its field's name). A scene's ``settings`` are one, its
    ``radius`` None unless the scene file gives one (the scene's default, 1%
    of its diagonal); ``Engine.run_params`` gives one with every value set.
    Change one with ``dataclasses.replace``."""

    # The fast DETP: plain "detp" gives the same sums but tests every
    # segment against every disc (the oracle), minutes where this takes seconds.
    method: str = "detp_disc_index"
    photons: int = 100_000
    radius: float | None = None
    seed: int = 1
    max_depth: int = 16
    extension: float = 0.0
    count_emitted: bool = True

    def __post_init__(self):
        for key in RUN_KEYS:
            value = getattr(self, key)
            if not (key == "radius" and value is None):
                object.__setattr__(self, key, READERS[key](value, key))

    @classmethod
    def read(cls, values: dict, names: dict | None = None, base: RunParams | None = None) -> RunParams:
        """``base`` (default: the defaults) with ``values``, each read under
        its name in ``names`` (default: its key), in the order given."""
        unknown = set(values) - set(RUN_KEYS)
        if unknown:
            raise OclgiError(f"unknown run parameter(s) {sorted(unknown)} (they are {', '.join(RUN_KEYS)})")
        names = names or {}
        checked = {k: READERS[k](v, names.get(k, k)) for k, v in values.items()}
        return dataclasses.replace(base if base is not None else cls(), **checked)
