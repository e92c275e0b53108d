# grazing_control: virtual environment, tests, demo, benchmarks.
# Needs only python3.11 and make (plus access to the package index for `make venv`).

VENV ?= .venv
PY = $(VENV)/bin/python
# The ros-jazzy-* wheels are cp311: the environment must be CPython 3.11.
PYTHON ?= python3.11
BENCHES = $(sort $(wildcard benchmarks/bench_*.py))

.DEFAULT_GOAL := help
.PHONY: help venv test demo figures bench constraints clean

help:
	@echo "make venv         create $(VENV) (pinned: requirements.txt + constraints.txt) and install the package editable"
	@echo "make test         run the test suite on three workers over both cores (one BLAS thread each): $(PY) -m pytest -n 3 --dist loadgroup --reruns 2 tests"
	@echo "make demo         run the demo: $(VENV)/bin/grazing demo --out out/demo"
	@echo "make figures      the study's Figs. 1 and 2: $(VENV)/bin/grazing figures --out out/figures"
	@echo "make bench        run every benchmarks/bench_*.py"
	@echo "make constraints  re-pin constraints.txt from requirements.txt (full freeze of a fresh venv)"
	@echo "make clean        remove $(VENV) and everything generated (out/, build/, install/, log/, caches, tests/js/node_modules)"

# Two stamps, each written last so that an interrupted step is redone on the next run.
# $(VENV)/.deps: the venv, recreated from scratch whenever a pin changes.
# --no-compile: pip byte-compiled every module of every wheel (all of scipy, matplotlib,
# dask, distributed, their tests), most of which nothing imports: the requirements'
# install took 123 s with it and 51 s without (load 10; 39 s against 24 s at load 4); a
# module is compiled when it is first imported instead (the imports of the CLI, rclpy,
# matplotlib, scipy.optimize, numba, pytest: 2 s of CPU once, cached in __pycache__).
# .ci/install_requirements.py: uv where it can be had (parallel downloads), else pip as
# before (GRAZING_INSTALLER=pip forces it); uv compiles no bytecode either.
# compileall: the bytecode is then written once, in parallel, leaving out the packages'
# own tests (7 s wall, 11 CPU-s on the two cores). Compiling on first import is not
# enough: a shell that sets PYTHONDONTWRITEBYTECODE=1 (this machine's does) never writes
# the cache, and every process compiled its imports again: a 1300-period `grazing run`
# from such a shell had an overhead of 3.49 s against 1.32 s with the bytecode
# (docs/benchmarks.md, "The bytecode written at install").
# A stamp of its own, so that a venv built before this step gets its bytecode too.
SITE_PACKAGES = $(VENV)/lib/python3.11/site-packages
$(VENV)/.deps: requirements.txt constraints.txt .ci/install_requirements.py
	rm -rf $(VENV)
	$(PYTHON) -m venv $(VENV)
	$(PY) .ci/install_requirements.py
	touch $@

$(VENV)/.bytecode: $(VENV)/.deps
	$(PY) -m compileall -q -j 0 -x '/tests?/' $(SITE_PACKAGES) > /dev/null
	touch $@

# $(VENV)/.stamp: the package, installed editable. The editable install maps the
# top-level packages found at install time (modules added inside them need no
# reinstall), so the packages' __init__.py files are prerequisites too: a package that
# appears later gets mapped. --no-build-isolation: the editable wheel is built by the
# venv's pinned setuptools, not by whatever version the index serves that day.
PKG_INITS = $(wildcard grazing_control/__init__.py sim_node/__init__.py)
$(VENV)/.stamp: $(VENV)/.bytecode setup.py setup.cfg package.xml $(PKG_INITS)
	$(PY) -m pip install --no-compile --no-deps --no-build-isolation -e .
	$(PY) -m compileall -q grazing_control sim_node drivers > /dev/null
	touch $@

venv: $(VENV)/.stamp

# BYTECODE: Python writes its bytecode cache (__pycache__) even where the environment
# sets PYTHONDONTWRITEBYTECODE (this machine's shell does). With it set, and the
# venv installed --no-compile, every process the tests start (each node, each `grazing`
# command: hundreds) compiled numba, scipy, rclpy and matplotlib from source again: a
# one-test node scene took 4.3 s on a fresh clone against 2.5 s with the cache, and the
# suite on a fresh clone 682 s against 532 s (docs/benchmarks.md, "The suite").
BYTECODE = PYTHONDONTWRITEBYTECODE=

# --no-loadscope-reorder: the groups in collection order, the realtime group last (xdist's
# default runs the largest groups first: the realtime one, whose tests wait for an idle
# other worker, came first and waited while the other worker ran the rest).
# --reruns: a test that fails is run again (up to twice) and reported as rerun; the node
# tests run real processes over Fast DDS on a 2-core machine, where scheduling can make a
# timing assertion miss. A deterministic failure still fails. --rerun-show-tracebacks: each
# failed attempt's traceback is printed (a rerun is a race to find, not a pass).
# -n 3 on the 2 cores: the node scenes wait (discovery, a scene's pace, a process's exit)
# with their cores partly idle; a third worker fills them. The suite at idle with the
# bytecode cache: 532 s on two workers (139 % CPU), 475 s on three (163 %), the same 2638
# tests passing, none rerun; the realtime group still runs alone (tests/conftest.py).
# One BLAS thread per process: the workers share the two cores, and OpenBLAS's own
# threads spinning beside them made tests/test_identification.py 2.4x slower at load 5-8.
test: $(VENV)/.stamp
	$(BYTECODE) OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 $(PY) -m pytest -q -r fER -n 3 --dist loadgroup --no-loadscope-reorder --reruns 2 --reruns-delay 1 --rerun-show-tracebacks tests

demo: $(VENV)/.stamp
	$(BYTECODE) $(VENV)/bin/grazing demo --out out/demo

figures: $(VENV)/.stamp
	$(VENV)/bin/grazing figures --out out/figures

bench: $(VENV)/.stamp
	@test -n "$(BENCHES)" || echo "no benchmarks/bench_*.py yet"
	@set -e; for b in $(BENCHES); do echo "== $$b"; $(PY) $$b; done

LOCKVENV = $(VENV)-lock
constraints:
	rm -rf $(LOCKVENV)
	$(PYTHON) -m venv $(LOCKVENV)
	$(LOCKVENV)/bin/python -m pip install --upgrade pip
	$(LOCKVENV)/bin/python -m pip install -r requirements.txt
	{ echo "# Full freeze of a venv built from requirements.txt (make constraints). Do not edit."; \
	  $(LOCKVENV)/bin/python -m pip freeze --all; } > constraints.txt
	rm -rf $(LOCKVENV)

clean:
	rm -rf $(VENV) $(LOCKVENV) out build install log .pytest_cache benchmarks/out *.egg-info \
		tests/js/node_modules
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
