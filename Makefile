# The two set-up commands of the README. Each bootstraps .venv/ on a fresh machine (Python >= 3.10 only).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo demo-real test bench fuzz clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

# A simulated walk (needs no data and no network): phone in the hand, GNSS with outliers, 70 s indoors. Prints the
# one-line summary and the errors against the simulator's truth; warnings are in out/demo/summary.json.
demo: $(VENV)/.installed
	$(BIN)/pdr simulate configs/sim/demo_phone_walk.toml -o out/demo_recording --seed 1 --force > /dev/null
	$(BIN)/pdr run out/demo_recording -o out/demo --plot --force 2> /dev/null
	$(BIN)/pdr evaluate out/demo out/demo_recording | $(BIN)/python -c "import json, sys; m = json.load(sys.stdin); \
	print(f\"against the truth: distance {m['distance_error_pct']:+.2f}%, final error {m['final_error_m']:.2f} m, \
	position RMSE {m['ate_rmse_m']:.2f} m, steps {m['n_steps']} of {m['n_steps_ref']} (F1 {m['step_f1']:.3f})\")"

# The real HuMoLiRe phone walk (120.8 m, two laps, no GNSS) through the dataset registry: needs the data
# (../shared/datasets, PDR_DATA_DIR, or `pdr datasets fetch humolire_phone_landmarks` first).
demo-real: $(VENV)/.installed
	$(BIN)/pdr import humolire "$$($(BIN)/pdr datasets path humolire_phone_landmarks)/data/imus/1/square_2x" \
	out/demo_real_recording --force > /dev/null
	$(BIN)/pdr run out/demo_real_recording/square_2x -o out/demo_real --plot --force

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
