"""Shared fixtures; ``--run-slow`` enables the studies marked ``slow``; the files that
compile the same kernels run in one pytest-xdist worker."""

import numpy as np
import pytest

import fastvi


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False, help="run tests marked slow")


#: test files that compile the same family of kernels beyond the plain step and time loop.
#: Most of the suite's time is numba compiling; two workers that both need a family each
#: compile it (the on-disk cache helps only once one of them has finished), so under
#: ``--dist loadfile`` every file of a family goes to one worker, in one work unit.
KERNEL_FAMILIES = {
    "derivatives": ("test_hard_cases", "test_lyapunov", "test_mass_params",
                    "test_off_constraint_start", "test_param_patterns", "test_periodic",
                    "test_periodic_forced",
                    "test_sensitivity", "test_sensitivity_ensemble",
                    "test_sensitivity_structured", "test_singular_mass_derivatives",
                    "test_sized_tangent"),
    "structured": ("test_bodies", "test_bodies_dynamics", "test_chain", "test_patterns",
                   "test_sparse", "test_tree"),
    "ensembles": ("test_distributed", "test_drawing", "test_ensemble"),
    "baselines": ("test_baselines", "test_results"),
}
_FAMILY_OF = {f"tests/{name}.py": family for family, names in KERNEL_FAMILIES.items()
              for name in names}


def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadfile":
        return None
    from pathlib import Path

    from xdist.scheduler import LoadFileScheduling

    here = Path(__file__).parent
    missing = [p for p in _FAMILY_OF if not (here.parent / p).exists()]
    if missing:  # a renamed file would silently leave its family
        raise pytest.UsageError(f"tests/conftest.py KERNEL_FAMILIES names no such file: {missing}")

    class KernelFamilyScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid):
            path = super()._split_scope(nodeid)
            return _FAMILY_OF.get(path, path)

    return KernelFamilyScheduling(config, log)


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
