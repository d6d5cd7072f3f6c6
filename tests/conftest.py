"""Shared fixtures. Tests run on the default OpenCL device (PoCL's CPU
device in CI); a missing device fails the run, it never skips."""

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"


@pytest.fixture(scope="session")
def cl_env():
    from oclgi.cl.device import create_context

    return create_context()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def scenes_dir():
    return SCENES
