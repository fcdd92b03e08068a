# Two commands: `make demo` and `make test`. Both set up .venv (CPython 3.11) first.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
BROWSER := $(VENV)/.browser
FUZZ   := $(VENV)/.fuzz
OUT    ?= runs/demo
PYTEST_ARGS ?=

.PHONY: setup demo test lint screenshots bench bench-smoke survey survey-smoke experiments experiments-smoke fuzz \
        fuzz-smoke clean

setup: $(STAMP)

$(STAMP): pyproject.toml requirements.lock
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else "swarm-sitl needs CPython 3.11 (pybullet 3.2.7 has wheels only up to 3.11); set PYTHON=/path/to/python3.11")'
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --only-binary :all: -r requirements.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

# a headless browser (Qt WebEngine from PyPI, about 210 MB), for the tests and screenshots only: `make demo` skips it
$(BROWSER): $(STAMP) requirements-browser.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --only-binary :all: -r requirements-browser.lock
	@touch $(BROWSER)

# atheris (libFuzzer for Python, a cp311 wheel), for the fuzz targets only: `make demo` and `make test` skip it
$(FUZZ): $(STAMP) requirements-fuzz.lock
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --only-binary :all: -r requirements-fuzz.lock
	@touch $(FUZZ)

demo: $(STAMP)
	$(BIN)/swarm-sitl run hil_configs/demo.toml --out $(OUT)

# three workers on two cores: a third keeps them busy while the paced (wall-clock) HIL tests wait
test: $(STAMP) $(BROWSER)
	$(BIN)/ruff check bridge firmware_sim swarm_logic tests examples fuzz
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -n 3 --dist worksteal -q $(PYTEST_ARGS)

lint: $(STAMP)
	$(BIN)/ruff check bridge firmware_sim swarm_logic tests examples fuzz
	$(BIN)/lint-imports

bench: $(STAMP)
	$(BIN)/swarm-sitl bench
	$(BIN)/swarm-sitl bench --scale
	$(BIN)/swarm-sitl bench --study rdpso
	$(BIN)/swarm-sitl bench --study zebro
	$(BIN)/swarm-sitl bench --study pfsm

bench-smoke: $(STAMP)
	$(BIN)/swarm-sitl bench --quick
	$(BIN)/swarm-sitl bench --study rdpso --quick
	$(BIN)/swarm-sitl bench --study zebro --quick
	$(BIN)/swarm-sitl bench --study pfsm --quick

survey: $(STAMP)
	$(BIN)/swarm-sitl radio-survey hil_configs/demo.toml --out runs/radio-survey

survey-smoke: $(STAMP)
	$(BIN)/swarm-sitl radio-survey hil_configs/demo.toml --duration 300 --out runs/radio-survey-smoke --quiet

# every parser a byte from outside reaches (fuzz/), each 10^5 inputs or 10 minutes under atheris; what reached new code
# is merged into fuzz/corpus/ (commit it); fails naming the reproducer if any input crashed or hung a parser
fuzz: $(STAMP) $(FUZZ)
	$(BIN)/swarm-sitl fuzz --runs 100000 --max-time 600 --merge

fuzz-smoke: $(STAMP) $(FUZZ)
	$(BIN)/swarm-sitl fuzz --runs 2000 --max-time 10 --out runs/fuzz-smoke --quiet

# `swarm-sitl experiment NAME $(1)` for every registered experiment; fails if any had a failed trial
define each_experiment
	@names=$$($(BIN)/swarm-sitl experiment --list) || exit 1; status=0; \
	for e in $$(printf '%s\n' "$$names" | cut -d' ' -f1); do \
		echo "$(BIN)/swarm-sitl experiment $$e$(if $(1), $(1))"; $(BIN)/swarm-sitl experiment $$e $(1) || status=1; \
	done; exit $$status
endef

experiments: $(STAMP)
	$(call each_experiment,)

experiments-smoke: $(STAMP)
	$(call each_experiment,--smoke --quiet)

# the README's pictures of the run report, from a 60-s demo run, rendered in the headless browser
screenshots: $(STAMP) $(BROWSER)
	$(BIN)/swarm-sitl run hil_configs/demo.toml --duration 60 --quiet --out runs/screenshots
	$(BIN)/swarm-sitl report runs/screenshots --screenshot docs/img/report-top.png --height 1150
	$(BIN)/swarm-sitl report runs/screenshots --screenshot docs/img/report-connectivity.png --section connectivity
	$(BIN)/swarm-sitl report runs/screenshots --screenshot docs/img/report-radio.png --section rssi

clean:
	rm -rf $(VENV) runs build *.egg-info .pytest_cache .ruff_cache
