"""The API docstring examples run as written."""

import doctest

import pytest

import oclgi.engine
import oclgi.photon_map_session
import oclgi.session


@pytest.mark.parametrize("module", [oclgi.engine, oclgi.session, oclgi.photon_map_session])
def test_docstring_examples(module):
    result = doctest.testmod(module, verbose=False)
    assert result.attempted >= 2
    assert result.failed == 0
