"""The API docstring examples run as written."""

import doctest

import oclgi.engine


def test_engine_docstring_example():
    result = doctest.testmod(oclgi.engine, verbose=False)
    assert result.attempted >= 4
    assert result.failed == 0
