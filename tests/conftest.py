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
    "derivatives": ("test_hard_cases", "test_lyapunov", "test_param_patterns", "test_periodic",
                    "test_sensitivity", "test_sensitivity_ensemble",
                    "test_sensitivity_structured", "test_sized_tangent"),
    "structured": ("test_bodies", "test_bodies_dynamics", "test_chain", "test_patterns",
                   "test_sparse", "test_tree"),
    "ensembles": ("test_distributed", "test_drawing", "test_ensemble"),
    "baselines": ("test_baselines", "test_results"),
}
_FAMILY_OF = {f"tests/{name}.py": family for family, names in KERNEL_FAMILIES.items()
              for name in names}
#: files with few tests that take long (subprocesses, kernels compiled for a model's sizes).
#: The work units start in the order: the families, these, then the others by their number
#: of tests (pytest-xdist's own order, which would start these last and leave one worker
#: idle while the other finishes one of them)
LONG_FILES = ("test_examples", "test_specialize", "test_memory_safety", "test_symbolic")
_EARLY = [*KERNEL_FAMILIES, *(f"tests/{name}.py" for name in LONG_FILES)]


def _work_unit(nodeid):
    path = nodeid.split("::", 1)[0]
    return _FAMILY_OF.get(path, path)


def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadfile":
        return None
    from pathlib import Path

    from xdist.scheduler import LoadFileScheduling

    root = Path(__file__).parent.parent
    missing = [p for p in [*_FAMILY_OF, *_EARLY[len(KERNEL_FAMILIES):]] if not (root / p).exists()]
    if missing:  # a renamed file would silently leave its family or its place
        raise pytest.UsageError(f"tests/conftest.py names no such test file: {missing}")
    config.option.loadscopereorder = False  # the workers' collection is in order already

    class KernelFamilyScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid):
            return _work_unit(nodeid)

    return KernelFamilyScheduling(config, log)


def pytest_collection_modifyitems(config, items):
    if hasattr(config, "workerinput"):  # a pytest-xdist worker: the order of the work units
        sizes = {}
        for item in items:
            unit = _work_unit(item.nodeid)
            sizes[unit] = sizes.get(unit, 0) + 1

        def rank(item):
            unit = _work_unit(item.nodeid)
            return (0, _EARLY.index(unit)) if unit in _EARLY else (1, -sizes[unit])

        items.sort(key=rank)  # stable: a unit's tests keep their order
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
