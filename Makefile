# The two set-up commands of the README. Each bootstraps .venv/ on a fresh machine (Python >= 3.10 only).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test bench fuzz clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

demo: $(VENV)/.installed
	rm -rf out/demo_recording
	$(BIN)/pdr import humolire datasets/humolire_phone_landmarks/data/imus/1/square_2x out/demo_recording > /dev/null
	$(BIN)/pdr run out/demo_recording/square_2x -o out/demo --plot

test: $(VENV)/.installed-dev
	$(BIN)/python -m pytest

# The long fuzz of tests/test_fuzz.py: PDR_FUZZ_EXAMPLES cases per target (default 1,200; 12 targets: > 10,000
# cases), counts in out/fuzz/stats.json. `make test` runs the short profile (25 derandomised cases per target).
fuzz: $(VENV)/.installed-dev
	PDR_FUZZ=long $(BIN)/python -m pytest -q tests/test_fuzz.py

bench: $(VENV)/.installed-dev
	$(BIN)/python -m benchmarks

clean:
	rm -rf out .pytest_cache
