"""IES LM-63 photometric files: read, checked, expanded and tabulated for sampling.

A lighting designer's luminaire comes as an IES file (ANSI/IES LM-63, the
1986, 1991, 1995 and 2002 editions share the layout read here): keyword
lines (``[TEST]``, ``[MANUFAC]``, ...), ``TILT=NONE``, then numbers
separated by blanks or commas over any number of lines:

    lamps  lumens_per_lamp  multiplier  n_vertical  n_horizontal
    photometric_type  units  width  length  height
    ballast_factor  ballast_lamp_factor (2002: "future use", 1)  input_watts
    n_vertical angles, n_horizontal angles (degrees, ascending)
    n_horizontal rows of n_vertical candela values

Read here: photometric type C only (the vertical angle gamma from the
nadir, 0 straight down, to 180 straight up; the horizontal angle C about
the vertical axis, counter-clockwise seen from above), TILT=NONE only (a
tilt table would make the output depend on the luminaire's mounting).
The candela are the values times the multiplier, the ballast factor and
the ballast-lamp factor. The usual symmetries of the horizontal angles are
expanded to the whole circle: a last angle of 0 (one plane: the same in
every direction), 90 (each quadrant mirrors the first), 180 (the half
C 180..360 mirrors 0..180) or 360 (no symmetry; the plane at 360 is the
one at 0).

The distribution is piecewise constant over bins, one per tabulated
(vertical, horizontal) pair, centred on it: a bin reaches half-way to the
neighbouring angles, the first and last vertical bins end at the first and
last vertical angles (no light beyond them), the horizontal bins wrap
around the circle. So the intensity in the direction of a tabulated angle
is the file's value there, and a bin's solid angle is
(cos gamma_lo - cos gamma_hi) x (C_hi - C_lo) in radians. Directions are
sampled bin by bin in proportion to intensity x solid angle (a row of the
marginal CDF, then a column of its conditional CDF, uniform in cos gamma
and in C within the bin: kernels/light.h), so every photon of a point
light carries the same power.

Fuzz-safe: the file is read up to MAX_BYTES, counts are checked against
MAX_ANGLES and MAX_VALUES before any table is made, and every problem is
one OclgiError line naming the file.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import OclgiError

MAX_BYTES = 8 << 20  # an IES file of 181 x 361 values is about 0.5 MB
MAX_ANGLES = 3601  # 0.1 degree steps over the whole circle
MAX_VALUES = 1 << 21  # candela values (vertical x horizontal)
PHOTOMETRIC_TYPE_C = 1
HEADER_NUMBERS = 13  # the numbers before the angles (two lines of 10 and 3)
SYMMETRIES = (0.0, 90.0, 180.0, 360.0)  # the last horizontal angles read
_SEPARATORS = re.compile(r"[\s,]+")


@dataclass(eq=False)
class IesProfile:
    """A type C luminaire's intensity distribution, expanded to the whole circle.

    ===========  ==============================================================
    vertical     (V,) vertical angles gamma, degrees, ascending, in [0, 180]
    horizontal   (H,) horizontal angles C, degrees, ascending, in [0, 360)
    candela      (H, V) luminous intensity, cd, at each (C, gamma)
    rated        the file's lamp lumens (lamps x lumens per lamp), or None
                 (absolute photometry, ``-1``)
    name         the file's name, for messages
    ===========  ==============================================================
    """

    vertical: np.ndarray
    horizontal: np.ndarray
    candela: np.ndarray
    rated: float | None = None
    name: str = "ies"

    def vertical_edges(self) -> np.ndarray:
        """(V + 1,) bin edges in gamma, degrees: the first and last angles, and midpoints between."""
        v = self.vertical
        return np.concatenate([v[:1], 0.5 * (v[1:] + v[:-1]), v[-1:]])

    def horizontal_edges(self) -> np.ndarray:
        """(H + 1,) bin edges in C, degrees, ascending over one turn: midpoints,
        the first bin reaching back across 0 (it may start below 0)."""
        h = self.horizontal
        if len(h) == 1:
            return np.array([h[0] - 180.0, h[0] + 180.0])
        mids = 0.5 * (h[1:] + h[:-1])
        first = 0.5 * (h[-1] - 360.0 + h[0])
        return np.concatenate([[first], mids, [first + 360.0]])

    def bin_solid_angles(self) -> np.ndarray:
        """(H, V) solid angle of each bin, sr."""
        dcos = -np.diff(np.cos(np.radians(self.vertical_edges())))
        dphi = np.radians(np.diff(self.horizontal_edges()))
        return dphi[:, None] * dcos[None, :]

    @property
    def lumens(self) -> float:
        """The luminous flux of the tabulated distribution: sum of candela x solid angle."""
        return float((self.candela * self.bin_solid_angles()).sum())

    @property
    def peak(self) -> float:
        return float(self.candela.max())

    def intensity(self, gamma_deg, c_deg) -> np.ndarray:
        """The distribution's candela in the directions (gamma, C), degrees
        (the bin each falls in; 0 outside the vertical range)."""
        g = np.asarray(gamma_deg, np.float64)
        c = np.asarray(c_deg, np.float64)
        ve, he = self.vertical_edges(), self.horizontal_edges()
        i = np.clip(np.searchsorted(ve, g, side="right") - 1, 0, len(self.vertical) - 1)
        c = he[0] + np.mod(c - he[0], 360.0)
        j = np.clip(np.searchsorted(he, c, side="right") - 1, 0, len(self.horizontal) - 1)
        inside = (g >= ve[0]) & (g <= ve[-1])
        return np.where(inside, self.candela[j, i], 0.0)


def read(path, where: str = "ies") -> IesProfile:
    """An IES file as an :class:`IesProfile`; one OclgiError line per problem."""
    path = Path(path)
    label = f"{where}: {path.name}"
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise OclgiError(f"{where}: IES file not found: {path}") from None
    except IsADirectoryError:
        raise OclgiError(f"{where}: {path} is a folder, not an IES file") from None
    except OSError as exc:
        raise OclgiError(f"{where}: cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_BYTES:
        raise OclgiError(f"{label}: larger than {MAX_BYTES >> 20} MiB; not an IES file oclgi reads")
    return parse(data, label, name=path.name)


def parse(data: bytes, label: str = "ies", name: str = "ies") -> IesProfile:
    """The profile of an IES file's bytes (``label`` starts every message)."""
    if b"\x00" in data:
        raise OclgiError(f"{label}: not a text file (an IES file is ASCII text)")
    lines = data.decode("latin-1").splitlines()
    tilt = next((k for k, line in enumerate(lines) if line.strip().upper().startswith("TILT")), None)
    if tilt is None:
        raise OclgiError(f"{label}: no TILT= line (not an IES LM-63 file)")
    value = lines[tilt].split("=", 1)[1].strip() if "=" in lines[tilt] else ""
    if value.upper() != "NONE":
        raise OclgiError(f"{label}: line {tilt + 1}: TILT={value or '?'}; only TILT=NONE is read (no tilt tables)")
    tokens = [(t, k + 1) for k in range(tilt + 1, len(lines)) for t in _SEPARATORS.split(lines[k].strip()) if t]
    if len(tokens) < HEADER_NUMBERS:
        raise OclgiError(f"{label}: {len(tokens)} numbers after TILT=NONE; the photometric header alone has "
                         f"{HEADER_NUMBERS}")

    def numbers(start: int, count: int, what: str) -> np.ndarray:
        out = np.empty(count)
        for n, (text, line) in enumerate(tokens[start:start + count]):
            try:
                out[n] = float(text)
            except ValueError:
                raise OclgiError(f"{label}: line {line}: {what}: not a number: {text[:20]!r}") from None
            if not math.isfinite(out[n]) or abs(out[n]) > 1e30:
                raise OclgiError(f"{label}: line {line}: {what}: {text[:20]!r} is not a finite number "
                                 "of a sane size")
        return out

    head = numbers(0, HEADER_NUMBERS, "photometric header")
    lamps, per_lamp, multiplier, nv, nh, ptype, _units, _w, _l, _h, ballast, ballast_lamp, _watts = head
    line = tokens[0][1]
    for count, what in ((nv, "vertical angles"), (nh, "horizontal angles")):
        if count != int(count) or not 1 <= count <= MAX_ANGLES:
            raise OclgiError(f"{label}: line {line}: the number of {what} is {count:g}; expected a whole number "
                             f"from 1 to {MAX_ANGLES}")
    nv, nh = int(nv), int(nh)
    if nv < 2:
        raise OclgiError(f"{label}: line {line}: one vertical angle; at least 2 are needed (the bins span them)")
    if nv * nh > MAX_VALUES:
        raise OclgiError(f"{label}: {nv} x {nh} candela values; at most {MAX_VALUES:,}")
    if ptype != PHOTOMETRIC_TYPE_C:
        kind = {2: "B", 3: "A"}.get(int(ptype) if ptype == int(ptype) else -1)
        raise OclgiError(f"{label}: line {line}: photometric type {ptype:g}"
                         f"{f' (type {kind})' if kind else ''}; only type C (1) is read")
    for x, what in ((multiplier, "candela multiplier"), (ballast, "ballast factor"),
                    (ballast_lamp, "ballast-lamp factor")):
        if not x > 0:
            raise OclgiError(f"{label}: the {what} is {x:g}; expected a number > 0")
    want = HEADER_NUMBERS + nv + nh + nv * nh
    if len(tokens) != want:
        more = "missing" if len(tokens) < want else "extra"
        raise OclgiError(f"{label}: {len(tokens)} numbers after TILT=NONE, expected {want} for {nv} vertical and "
                         f"{nh} horizontal angles ({abs(len(tokens) - want)} {more})")
    vertical = numbers(HEADER_NUMBERS, nv, "vertical angles")
    horizontal = numbers(HEADER_NUMBERS + nv, nh, "horizontal angles")
    values = numbers(HEADER_NUMBERS + nv + nh, nv * nh, "candela values").reshape(nh, nv)
    if not (np.diff(vertical) > 0).all() or vertical[0] < 0 or vertical[-1] > 180:
        raise OclgiError(f"{label}: vertical angles must ascend within 0..180 degrees, got "
                         f"{_show(vertical)}")
    if not (np.diff(horizontal) > 0).all() or horizontal[0] != 0 or horizontal[-1] not in SYMMETRIES:
        raise OclgiError(f"{label}: horizontal angles must ascend from 0 to 0, 90, 180 or 360 degrees (type C's "
                         f"symmetries), got {_show(horizontal)}")
    if (values < 0).any():
        k = int(np.argmax((values < 0).ravel()))
        raise OclgiError(f"{label}: candela value {k + 1} is negative ({values.ravel()[k]:g})")
    candela = values * (multiplier * ballast * ballast_lamp)
    horizontal, candela = expand(horizontal, candela)
    profile = IesProfile(vertical, horizontal, candela, rated=lamps * per_lamp if per_lamp > 0 and lamps > 0
                         else None, name=name)
    if not profile.lumens > 0:
        raise OclgiError(f"{label}: the candela table emits no light")
    return profile


def expand(horizontal: np.ndarray, candela: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A type C table's horizontal angles and (H, V) candela over the whole
    circle [0, 360), from the symmetry its last angle states."""
    last = horizontal[-1]
    if last == 0:  # one plane for every direction
        return horizontal, candela
    if last == 90:  # quadrant symmetry: first mirror about the 90 degree plane, then as below
        horizontal, candela = _mirror(horizontal, candela, 90.0)
    if last in (90, 180):  # bilateral: C and 360 - C alike
        horizontal, candela = _mirror(horizontal, candela, 180.0)
    if horizontal[-1] == 360:  # the plane at 360 is the one at 0
        horizontal, candela = horizontal[:-1], candela[:-1]
    return horizontal, candela


def _mirror(horizontal, candela, about: float):
    """Angles 0..about and their mirror images about..2 about (``about`` itself once)."""
    back = slice(-2, None, -1)
    return (np.concatenate([horizontal, 2 * about - horizontal[back]]),
            np.concatenate([candela, candela[back]]))


def _show(a: np.ndarray) -> str:
    text = ", ".join(f"{x:g}" for x in a[:6])
    return f"[{text}{', ...' if len(a) > 6 else ''}]"


# -- the device's tables ---------------------------------------------------------------------------------------

def smoothstep_integral(c_lo, c_hi, cos_total: float, cos_start: float) -> np.ndarray:
    """The integral over cos gamma in [c_lo, c_hi] of a spot's profile
    (pbrt-v4's smoothstep from cos_total to cos_start, kernels/light.h),
    exactly: with t = (c - cos_total) / (cos_start - cos_total), the
    smoothstep 3t^2 - 2t^3 integrates to t^3 - t^4 / 2, and 1 above."""
    c_lo, c_hi = np.asarray(c_lo, np.float64), np.asarray(c_hi, np.float64)
    width = cos_start - cos_total
    if width <= 0:  # a hard edge: the profile is 1 from cos_total up
        return np.clip(c_hi - np.maximum(c_lo, cos_total), 0.0, None) * (c_hi > c_lo)

    def antiderivative(c):
        t = (c - cos_total) / width
        inside = np.clip(t, 0.0, 1.0)
        return width * (inside**3 - inside**4 / 2 + np.clip(t - 1.0, 0.0, None))

    return antiderivative(c_hi) - antiderivative(c_lo)


def cdf_tables(weight: np.ndarray, total: float):
    """(row CDF (R,), column CDFs (R, C)) of a table of sampling weights
    summing to ``total``, as kernels/light.h samples it (a row, then a
    column of it); a dark row's CDF is uniform (it is never chosen)."""
    row = weight.sum(axis=1)
    rows = np.cumsum(row) / total
    rows[-1] = 1.0
    uniform = np.cumsum(np.ones_like(weight), axis=1) / weight.shape[1]
    cols = np.where(row[:, None] > 0, np.cumsum(weight, axis=1) / np.where(row > 0, row, 1.0)[:, None], uniform)
    cols[:, -1] = 1.0
    return rows, cols


def tables(profile: IesProfile, cos_total: float = -1.0, cos_start: float = -1.0):
    """(table, flux, bound): the device's table (kernels/light.h: V, H, the
    vertical edges as -cos gamma ascending, the horizontal edges in radians,
    the row CDF, the rows' column CDFs), the flux emitted (candela x sr:
    lumens), with a spot's profile from cos_total to cos_start (-1, -1: a
    point light, no cone) applied exactly, and the bound on the flux one
    photon carries times the photon count: photons sample the table (bins
    wholly outside the cone never), so a photon carries bound x the
    profile at its direction, <= bound."""
    ve, he = profile.vertical_edges(), profile.horizontal_edges()
    cos_e = np.cos(np.radians(ve))  # descending
    dphi = np.radians(np.diff(he))
    lit = cos_e[:-1] > cos_total if cos_total > -1 else np.ones(len(ve) - 1, bool)  # a bin reaching into the cone
    weight = profile.candela * dphi[:, None] * (-np.diff(cos_e))[None, :] * lit[None, :]  # (H, V)
    cone = smoothstep_integral(cos_e[1:], cos_e[:-1], cos_total, cos_start) if cos_total > -1 else -np.diff(cos_e)
    flux = float((profile.candela * dphi[:, None] * cone[None, :]).sum())
    bound = float(weight.sum())
    if not (flux > 0 and bound > 0):
        raise OclgiError(f"{profile.name}: no light of the IES profile falls within the spot's cone")
    w = weight.T  # (V, H): a row per vertical bin
    rows, cols = cdf_tables(w, bound)
    nv, nh = w.shape
    table = np.concatenate([[nv, nh], -cos_e, np.radians(he), rows, cols.ravel()])
    return table, flux, bound
