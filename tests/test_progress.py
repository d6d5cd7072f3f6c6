"""Progress in its three modes: a bar on a terminal (tqdm, or the hand-drawn
one without it), a widget or bar in a notebook, lines every period in a log,
and nothing when it is off. Always on the stream it is given (stderr), never
on stdout; no assertion on how long anything takes (the clock is a fake)."""

import io
import sys
import types

from oclgi import progress
from oclgi.progress import Progress


class _Clock:
    now = 100.0

    def __call__(self):
        return self.now


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_off_a_terminal_is_a_line_every_period_with_the_time_left():
    stream, clock = io.StringIO(), _Clock()
    bar = Progress("detp", 20_000_000, stream=stream, period=10.0, clock=clock)
    assert bar.bar is None  # a log: no tqdm bar
    clock.now += 4.0
    bar.update(2_000_000)
    assert stream.getvalue() == ""  # shorter than a period: nothing yet
    clock.now += 6.55
    bar.update(5_300_000)  # 36.5% after 10.55 s: 18.3 s left
    assert stream.getvalue() == "oclgi: detp 36% (7.3M of 20M paths), 18 s left\n"
    clock.now += 1.0
    bar.update(1_000_000)
    assert stream.getvalue().count("\n") == 1  # one line per period
    clock.now += 10.0
    bar.update(1_700_000)
    assert stream.getvalue().splitlines()[1] == "oclgi: detp 50% (10M of 20M paths), 22 s left"
    bar.update(10_000_000)
    bar.close()
    assert stream.getvalue().count("\n") == 2  # nothing at 100% nor on close


def test_progress_on_a_terminal_is_a_tqdm_bar_redrawn_in_place(capsys):
    import tqdm
    stream = _Tty()
    bar = Progress("detp", 1000, stream=stream, clock=_Clock())
    assert isinstance(bar.bar, tqdm.tqdm)
    bar.update(250)
    bar.update(250)
    assert bar.bar.n == 500 and bar.bar.total == 1000
    bar.bar.refresh()  # tqdm draws at most every 0.1 s of its own clock: draw now
    drawn = stream.getvalue()
    assert drawn.startswith("\r") and "detp" in drawn and "50%" in drawn and "500/1.00k" in drawn
    bar.close()
    assert "\n" not in stream.getvalue()  # redrawn in place, and gone on close (the summary follows)
    assert capsys.readouterr().out == ""


def test_progress_on_a_terminal_without_tqdm_is_the_hand_drawn_bar(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm raises ImportError
    stream, clock = _Tty(), _Clock()
    bar = Progress("detp", 1000, stream=stream, clock=clock)
    assert bar.bar is None
    clock.now += 1.0
    bar.update(250)
    assert stream.getvalue().startswith("\rdetp [#######") and " 25.0%" in stream.getvalue()
    assert "\n" not in stream.getvalue()


def _fake_kernel(monkeypatch):
    shell = types.SimpleNamespace(config={"IPKernelApp": {}})
    monkeypatch.setitem(sys.modules, "IPython", types.SimpleNamespace(get_ipython=lambda: shell))


def test_progress_in_a_notebook_is_tqdm_not_log_lines(monkeypatch, capsys):
    assert not progress.in_notebook()
    _fake_kernel(monkeypatch)
    assert progress.in_notebook()
    stream, clock = io.StringIO(), _Clock()  # a kernel's stderr is no terminal
    bar = Progress("detp", 1000, stream=stream, clock=clock)
    assert bar.bar is not None  # tqdm.auto's widget, or its text bar where ipywidgets is missing
    clock.now += 60.0
    bar.update(1000)
    bar.close()
    assert "oclgi: detp" not in stream.getvalue()  # no log lines
    assert capsys.readouterr().out == ""


def test_progress_disabled_prints_nothing(monkeypatch):
    _fake_kernel(monkeypatch)  # not in a notebook either
    for stream in (io.StringIO(), _Tty()):
        clock = _Clock()
        bar = Progress("detp", 10, enabled=False, stream=stream, period=0.0, clock=clock)
        assert bar.bar is None
        clock.now += 60
        bar.update(5)
        bar.close()
        assert stream.getvalue() == ""
