# primspace: the two commands a new user runs are `make demo` and `make test`.
# Each does its own set-up in .venv. torch is pinned to 2.13.0 and taken from PyTorch's CPU index
# (TORCH_INDEX): from the public index alone, `torch==2.13.0` is the CUDA build with about 20
# nvidia-*/cuda-* packages (several GB). Where the CPU index does not answer (a machine that reaches
# only a local index, which holds the CPU wheel), torch comes from pip's configured index, and
# `make` says so in one line. docs/performance.md, "Install": the dry-run reports of both.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
TORCH  ?= torch==2.13.0
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
# gymnasium-robotics is installed without its dependencies: we only read the Franka
# Panda model files it bundles (it would otherwise pull gymnasium and friends).
ROBOT_ASSETS := gymnasium-robotics==1.4.2

.PHONY: demo test test-fast lint docs install install-test bench clean

$(VENV)/bin/activate:
	@$(PYTHON) -c "import sys; sys.exit(sys.version_info < (3, 11))" || { \
		echo "primspace needs Python >= 3.11 (pyproject's requires-python); $(PYTHON) is older: make PYTHON=python3.11 ..." >&2; \
		exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

# torch first, from the CPU index when it answers (one quick probe, not pip's retries on every
# package; otherwise no separate call: the next one resolves it with the project); then the
# project with torch's pin, which the installed CPU wheel satisfies. The plain install has the
# `predict` extra (`primspace act` and ProMP need it); the test install is a superset of it (so
# it marks both, and `make demo` after `make test` installs nothing again).
DEMO_EXTRAS := [predict]
TEST_EXTRAS := [test,ray,video,predict]
define install_project
	@if $(PY) -c "import urllib.request; urllib.request.urlopen('$(TORCH_INDEX)/torch/', timeout=20)" 2>/dev/null; then \
		echo "torch: the CPU wheel from $(TORCH_INDEX)"; \
		$(PIP) install --quiet --index-url $(TORCH_INDEX) $(TORCH); \
	else \
		echo "torch: $(TORCH_INDEX) does not answer; $(TORCH) from pip's configured index (from the public index alone that is the CUDA build)"; \
	fi
	$(PIP) install --quiet $(TORCH) -e '.$(1)'
	$(PIP) install --quiet --no-deps $(ROBOT_ASSETS)
endef

$(VENV)/.installed: $(VENV)/bin/activate pyproject.toml
	$(call install_project,$(DEMO_EXTRAS))
	touch $@

$(VENV)/.installed-test: $(VENV)/bin/activate pyproject.toml
	$(call install_project,$(TEST_EXTRAS))
	touch $(VENV)/.installed $@

install: $(VENV)/.installed
install-test: $(VENV)/.installed-test

demo: install
	$(VENV)/bin/primspace demo

lint: install-test
	$(VENV)/bin/ruff check src tests benchmarks docs
	$(VENV)/bin/ruff format --check src tests benchmarks docs

# pytest-xdist: one worker per core; each test module runs whole on one worker (its module
# fixtures built once), the modules with the most `slow` tests first (tests/conftest.py).
# PYTEST_WORKERS=0 runs every test in one process; PYTEST_ARGS adds options (-k, a path, -x).
PYTEST_WORKERS ?= auto
PYTEST_XDIST   ?= -n $(PYTEST_WORKERS) --dist loadfile --no-loadscope-reorder

# the project's bytecode written once, up front: where PYTHONDONTWRITEBYTECODE is set (as on
# these machines) every process the tests start would otherwise compile primspace again
BYTECODE := $(PY) -m compileall -q -j 0 src tests

test: install-test lint
	$(BYTECODE) > /dev/null
	$(PY) -m pytest $(PYTEST_XDIST) $(PYTEST_ARGS)

# the edit-and-check loop: every test not marked `slow` (under 3 minutes on 2 cores)
test-fast: install-test lint
	$(BYTECODE) > /dev/null
	$(PY) -m pytest -m "not slow" $(PYTEST_XDIST) $(PYTEST_ARGS)

# the docs' generated numbers (from docs/results/*.json) and the API reference (build/api/index.html)
docs: install-test
	$(PY) -m primspace.report.markdown
	$(PY) docs/build_api.py build/api

bench: install
	$(PY) benchmarks/bench_generate.py
	$(PY) benchmarks/bench_cluster.py
	$(PY) benchmarks/bench_train.py

clean:
	rm -rf $(VENV) build dist src/*.egg-info .pytest_cache .hypothesis
