"""Progress of a long run on stderr, with the time left.

Three ways, chosen by where stderr goes:

- a terminal: a bar redrawn in place, through tqdm (a hand-drawn ``\\r``
  bar where tqdm is not installed);
- a Jupyter notebook: tqdm.auto's widget (tqdm's text bar on stderr when
  the notebook has no ipywidgets);
- elsewhere (a log file, a CI job, a pipe): one line every PERIOD seconds,
  such as

      oclgi: detp 36% (7.3M of 20M paths), 18 s left

  so that a long run under ``nohup`` or in a batch job still says how far
  it is; a run shorter than PERIOD prints nothing, so short runs' stderr
  stays empty.

Progress never goes to stdout; ``progress=False`` (``--quiet``) silences it.
"""

from __future__ import annotations

import importlib.util
import sys
import time

PERIOD = 10.0  # seconds between two lines when stderr is not a terminal


def count_text(n: int) -> str:
    """A count as people read it: 2,000; 35k; 7.3M; 20M; 1.2G."""
    if n < 10_000:
        return f"{n:,}"
    for scale, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= scale:
            x = n / scale
            if x >= 100 or x == int(x):  # round counts (a total, as given) without decimals
                return f"{x:.0f}{suffix}"
            return f"{x:.1f}{suffix}"
    return f"{n:,}"


def time_left_text(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s left"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min left"
    return f"{seconds / 3600:.1f} h left"


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (IPython under ipykernel), as tqdm.auto tells it."""
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None and hasattr(ipython, "get_ipython") else None
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})


def _tqdm(label: str, total: int, unit: str, stream, notebook: bool):
    """A tqdm bar, or None when tqdm is not installed. In a notebook,
    tqdm.auto's widget, or tqdm's text bar when the widget cannot be made
    (no ipywidgets; tqdm.notebook would raise ImportError when it draws)."""
    try:
        from tqdm import tqdm as text_bar
    except ImportError:
        return None
    # leave=False: the bar goes on close, as the summary line follows it
    options = {"desc": label, "total": total, "unit": f" {unit}", "unit_scale": True, "leave": False,
               "file": stream}
    # tqdm.auto warns on import when the notebook has no ipywidgets: ask first
    if notebook and importlib.util.find_spec("ipywidgets") is not None:
        try:
            from tqdm.auto import tqdm as auto_bar

            return auto_bar(**options)
        except ImportError:
            pass
    return text_bar(dynamic_ncols=True, **options)


class Progress:
    """``enabled``: None (default) shows progress (a bar on a terminal or in a
    notebook, periodic lines elsewhere), False nothing, True forces it.
    ``clock`` and ``period`` are there for tests (the periodic lines';
    tqdm keeps its own clock)."""

    def __init__(self, label: str, total: int, enabled: bool | None = None, stream=None,
                 unit: str = "paths", period: float = PERIOD, clock=time.monotonic):
        self.stream = stream or sys.stderr
        self.enabled = enabled is not False
        try:
            self.terminal = self.stream.isatty()
        except (AttributeError, ValueError):
            self.terminal = False
        self.label, self.total, self.done, self.unit = label, total, 0, unit
        self.period, self.clock = period, clock
        self.t0 = self.last = clock()
        notebook = self.enabled and not self.terminal and in_notebook()
        self.bar = _tqdm(label, total, unit, self.stream, notebook) if self.enabled and (
            self.terminal or notebook) else None

    def _time_left(self, frac: float, now: float) -> float:
        return (now - self.t0) * (1 - frac) / frac if frac > 0 else 0.0

    def update(self, amount: int):
        self.done += amount
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(amount)
            return
        now = self.clock()
        frac = min(self.done / max(self.total, 1), 1.0)
        left = self._time_left(frac, now)
        if self.terminal:
            bar = "#" * int(30 * frac)
            self.stream.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}%  eta {left:5.1f}s ")
            self.stream.flush()
        elif now - self.last >= self.period and self.done < self.total:
            self.last = now
            self.stream.write(f"oclgi: {self.label} {100 * frac:.0f}% ({count_text(self.done)} of "
                              f"{count_text(self.total)} {self.unit}), {time_left_text(left)}\n")
            self.stream.flush()

    def close(self):
        if self.bar is not None:
            self.bar.close()
        elif self.enabled and self.terminal:
            self.stream.write("\r" + " " * 70 + "\r")
            self.stream.flush()
