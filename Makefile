# Two commands set up a fresh machine and do the work (see README):
#   make demo   simulate the paper's experiment, train, evaluate, report (quick profile)
#   make test   the test suite (what CI runs)
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow test-all lint bench venv browser clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	# The local CPU wheel first: a bare `torch` requirement would pull GBs of CUDA packages.
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[live,dev]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/ectskin demo

# Chromium (Debian) for the dashboard's browser test. Fails loudly when it cannot be installed:
# a missing browser must stop `make test`, not turn the browser test into a silent skip.
CHROMIUM ?= /usr/bin/chromium
browser:
	@if [ ! -x "$(CHROMIUM)" ]; then \
		if ! command -v apt-get >/dev/null; then \
			echo "make browser: $(CHROMIUM) is missing and apt-get is not available; install Chromium there (the dashboard's browser test needs it)" >&2; \
			exit 1; \
		fi; \
		if ! (apt-get update -qq && apt-get install -y -qq chromium chromium-driver) >/dev/null; then \
			echo "make browser: could not install chromium with apt-get (the dashboard's browser test needs it)" >&2; \
			exit 1; \
		fi; \
		if [ ! -x "$(CHROMIUM)" ]; then \
			echo "make browser: apt-get installed chromium, but $(CHROMIUM) is still missing" >&2; \
			exit 1; \
		fi; \
	fi

test: $(STAMP) browser
	$(BIN)/python -m pytest

test-slow: $(STAMP)
	$(BIN)/python -m pytest -m "slow or ddp"

# Everything: the fast suite, the slow tests and the DDP tests (what CI runs).
test-all: $(STAMP) browser
	$(BIN)/python -m pytest -m "slow or ddp or not slow"

# ruff over all the code; mypy over the packages listed in pyproject.toml ([tool.mypy] files)
lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) demo-output .pytest_cache
