# Quick start: `make demo` and `make test` on a machine with only python3.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# the docs extra (Sphinx) only for `make docs`
DOCS_STAMP := $(VENV)/.docs-installed
# the bench extra (CyRK, the compiled peer) only for `make bench` / `make wpd`, not `make test`
BENCH_STAMP := $(VENV)/.bench-installed

# the byte code a process compiles (fastvi's modules, the tests' with pytest's assertions,
# the libraries', which pip leaves uncompiled: see --no-compile below) is kept for the next
# process even where the environment sets PYTHONDONTWRITEBYTECODE: the suite starts many
unexport PYTHONDONTWRITEBYTECODE

.PHONY: demo test test-slow bench paper-b orders wpd docs clean

# --no-compile: pip would byte-compile every module it installs (15 s of a 25 s install);
# Python compiles those a process imports, when it first imports them
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --no-compile -e ".[test,plot,dask,sym]"
	touch $(STAMP)

$(BENCH_STAMP): $(STAMP) pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[bench]"
	touch $(BENCH_STAMP)

$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

demo: $(STAMP)
	$(BIN)/python -m fastvi demo

# the suite's time is mostly numba compiling the kernels, one core a process: pytest-xdist
# runs the test files in TEST_JOBS processes (docs/benchmarks.md, "Compile and set-up time")
TEST_JOBS ?= 2

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist loadfile

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow --run-slow

bench: $(BENCH_STAMP)
	$(BIN)/python -m pytest bench -q --benchmark-only --benchmark-json=bench/results.json

paper-b: $(STAMP)
	$(BIN)/python -m fastvi paper-b --out docs

orders: $(STAMP)
	$(BIN)/python -m fastvi orders --out docs/orders.md

wpd: $(BENCH_STAMP)
	$(BIN)/python -m fastvi wpd --out docs

# the site in docs/_build/html; -W: a warning (a broken link, a bad docstring) fails the build.
# The examples are not executed (each compiles kernels for minutes): docs/conf.py.
docs: $(DOCS_STAMP)
	rm -rf docs/_build docs/generated docs/auto_examples
	$(BIN)/python -m sphinx -b html -W --keep-going -q docs docs/_build/html
	@echo "open docs/_build/html/index.html"

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache docs/_build docs/generated docs/auto_examples
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
