"""Shared fixtures; ``--run-slow`` enables the studies marked ``slow``."""

import numpy as np
import pytest

import fastvi


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False, help="run tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--run-slow"):
        return
    skip = pytest.mark.skip(reason="slow study: run with `make test-slow`")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def double_pendulum():
    return fastvi.scenes.double_pendulum()


@pytest.fixture(scope="session")
def pendulum():
    return fastvi.scenes.pendulum()


@pytest.fixture(scope="session")
def dp_start(double_pendulum):
    """Paper B's nonlinear start: θ1 = θ2 = π/2, at rest."""
    return double_pendulum.initial_state(np.pi / 2, np.pi / 2)
