"""The API docstring examples run as written."""

import doctest

import pytest

import oclgi.engine
import oclgi.incremental.photon_map_session
import oclgi.incremental.session
import oclgi.scene_parameters


@pytest.mark.parametrize("module", [oclgi.engine, oclgi.incremental.session, oclgi.incremental.photon_map_session,
                                    oclgi.scene_parameters])
def test_docstring_examples(module):
    result = doctest.testmod(module, verbose=False)
    assert result.attempted >= 2 and result.failed == 0
