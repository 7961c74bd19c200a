# pursuit — two commands on a fresh machine with python3 and pip:
#   make demo   set up .venv, reproduce every experiment, write results/
#   make test   set up .venv with the test extras, run the test suite

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
PYTEST_ARGS ?=

.PHONY: demo test bench clean help

help:
	@echo "make demo   reproduce every experiment under experiments/ into results/"
	@echo "make test   run the test suite"
	@echo "make bench  run the speed benchmarks (writes docs/benchmarks.md)"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@ $(VENV)/.installed

demo: $(VENV)/.installed
	$(BIN)/pursuit reproduce all --out results

test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n auto $(PYTEST_ARGS)

BENCH_VENV ?= .bench-venv

$(BENCH_VENV)/.installed: pyproject.toml benchmarks/requirements-peers.txt
	test -x $(BENCH_VENV)/bin/python || $(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet -e '.[fast]' -r benchmarks/requirements-peers.txt
	@touch $@

bench: $(BENCH_VENV)/.installed
	$(BENCH_VENV)/bin/python benchmarks/run.py

clean:
	rm -rf $(VENV) results .pytest_cache .hypothesis build dist
