"""The API docstring examples run as written."""

import doctest

import pytest

import oclgi.engine
import oclgi.incremental.photon_map_session
import oclgi.incremental.session
import oclgi.params
import oclgi.scene_parameters


@pytest.mark.parametrize("module, examples", [(oclgi.engine, 2), (oclgi.incremental.session, 2),
                                              (oclgi.incremental.photon_map_session, 2), (oclgi.scene_parameters, 2),
                                              (oclgi.params, 3)])
def test_docstring_examples(module, examples):
    result = doctest.testmod(module, verbose=False)
    assert result.attempted >= examples and result.failed == 0
