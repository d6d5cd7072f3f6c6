"""The README's Python blocks run as written, in order, in one namespace,
from a folder that holds the repository's scenes (as a user's checkout
does), and make what they say they make."""

import contextlib
import io
import re

import pytest
from conftest import ROOT

BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def _blocks():
    return BLOCK.findall((ROOT / "README.md").read_text())


def test_the_readme_has_python_blocks():
    assert len(_blocks()) >= 5


@pytest.mark.slow
def test_every_python_block_runs(tmp_path, monkeypatch):
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for i, code in enumerate(_blocks(), 1):
            exec(compile(code, f"README.md python block {i}", "exec"), namespace)  # noqa: S102
    assert "detp_disc_index: 200,000 photons" in out.getvalue()  # the first block's summary
    assert (tmp_path / "out" / "cornell.exr").is_file() and (tmp_path / "out" / "cornell.png").is_file()
    assert (tmp_path / "out" / "study" / "study.md").is_file()
    assert (tmp_path / "out" / "cmp" / "comparison.json").is_file()
    assert namespace["est"].irradiance.shape == (3, 3) and (namespace["est"].irradiance > 0).all()
