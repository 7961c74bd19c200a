# pursuit — two commands on a fresh machine with python3 and pip:
#   make demo   set up .venv, reproduce every experiment, write results/
#   make test   set up .venv with the test extras, run the test suite (all but the tests marked slow)
#   make test-slow / make test-all   the tests marked slow / everything (.ci/run runs both passes)

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
PYTEST_ARGS ?=

.PHONY: demo test test-slow test-all test-avx2-paths bench docs clean help

help:
	@echo "make demo   reproduce every experiment under experiments/ into results/"
	@echo "make test   run the test suite but the tests marked slow, on the serial numba builds (see docs/testing.md for its time)"
	@echo "make test-slow   run the tests marked slow: whole reproductions, benchmark scripts, million-step and many-run checks"
	@echo "make test-all   make test, then make test-slow"
	@echo "make test-avx2-paths   on an AVX-512 CPU, rerun the compiled, cross-check and robustness tests on NumPy's AVX2 paths"
	@echo "make bench  run the speed benchmarks (writes docs/benchmarks.md)"
	@echo "make docs   build the API reference (Sphinx, warnings are errors) into docs/_build/html"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@ $(VENV)/.installed

$(VENV)/.installed-docs: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	@touch $@ $(VENV)/.installed

# The API reference from the docstrings; -W: a warning (a docstring that does not parse) fails the build.
# tests/test_api_docs.py runs the same build in `make test-slow`.
docs: $(VENV)/.installed-docs
	$(BIN)/python -m sphinx -b html -W --keep-going docs/api docs/_build/html
	@echo "open docs/_build/html/index.html"

# --workers auto: the experiments side by side, one process per core this make may use (docs/cli.md);
# the files are the bits a serial run writes.  NumPy only: numba's cold compiles cost more than they save here.
# DEMO_MALLOC: glibc keeps freed memory instead of handing each large temporary back to the kernel
# (mmap/munmap, trim): 13 % of p1-wsn's and p3-upf's CPU was system time in page faults; it changes no number.
DEMO_MALLOC ?= MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=268435456 MALLOC_TOP_PAD_=67108864
demo: $(VENV)/.installed
	env $(DEMO_MALLOC) $(BIN)/pursuit reproduce all --workers auto --out results

# tests/conftest.py points numba's cache (and the generated kernels) at one folder under
# .test-cache/ for every worker and subprocess, named by a hash of src/pursuit/_compiled: the
# passes below compile each kernel about once between them (docs/testing.md#running-the-tests).
# --durations=15 lists the slowest tests of each pass: a new test over about 5 s gets the slow mark.
# PURSUIT_NUMBA_PARALLEL=0: the serial kernel builds only (same source, same bits); the parallel builds,
# four times the compile time, are compiled and checked against them in make test-slow.
test: $(VENV)/.installed-test
	PURSUIT_NUMBA_PARALLEL=0 $(BIN)/python -m pytest -n auto -m "not slow" --durations=15 $(PYTEST_ARGS)

test-slow: $(VENV)/.installed-test
	PURSUIT_NUMBA_PARALLEL=1 $(BIN)/python -m pytest -n auto -m slow --durations=15 $(PYTEST_ARGS)

test-all: test test-slow

# On a CPU with AVX-512, NumPy's elementary functions differ from the AVX2 ones in the last bit:
# run the tests that care a second time on NumPy's AVX2 paths (docs/compiled-backend.md).
AVX2_PATH_TESTS = tests/compiled tests/filters/test_conformance.py tests/filters/test_robustness.py tests/filters/test_perturbation.py

test-avx2-paths: $(VENV)/.installed-test
	@if grep -qw avx512f /proc/cpuinfo; then \
		NPY_DISABLE_CPU_FEATURES="X86_V4" $(BIN)/python -m pytest -n auto $(AVX2_PATH_TESTS); \
	else \
		echo "this CPU has no AVX-512: make test already ran NumPy's AVX2 paths"; \
	fi

BENCH_VENV ?= .bench-venv

$(BENCH_VENV)/.installed: pyproject.toml benchmarks/requirements-peers.txt
	test -x $(BENCH_VENV)/bin/python || $(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet -e '.[fast]' -r benchmarks/requirements-peers.txt
	@touch $@

bench: $(BENCH_VENV)/.installed
	$(BENCH_VENV)/bin/python benchmarks/run.py

clean:
	rm -rf $(VENV) results .pytest_cache .hypothesis .test-cache build dist docs/_build
