# make demo        — set up .venv with what the demo needs if missing, then run the main job on the default site
# make docs        — the same, then regenerate every figure and number the docs quote, from a fresh demo run
# make test        — set up .venv with the test tools if missing, install the system packages tests need (when root),
#                    check lint and formatting (ruff), then run the whole test suite
# make bench       — set up .venv with the test tools and the peers extra (the temporal planners benchmarks/peers.py
#                    compares with) if missing, then run every benchmark (JSON on stdout, files in benchmarks/results/)
# make constraints — re-resolve every dependency to its newest allowed version and pin it in constraints.txt

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
# One venv, two levels: what the demo needs (the package) and, on top, the test tools and extras.
# Each stamp says that level is installed for this pyproject.toml and these constraints.
STAMP_DEMO := $(VENV)/.installed-demo
STAMP_TEST := $(VENV)/.installed-test
# The versions CI installed (see `make constraints`): every install from this Makefile uses them.
CONSTRAINTS := constraints.txt

.PHONY: setup demo test lint bench docs constraints clean

# -qq: pip still prints errors (and fails the make), but not setuptools' notice about editable
# installs nor a machine's pip-config notices, which would greet every first run.
define install
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "installing $(1) and its dependencies into $(VENV) (versions from $(CONSTRAINTS); minutes the first time)"
	$(PY) -m pip install -qq --upgrade 'pip>=24,<27'
	$(PY) -m pip install -qq -c $(CONSTRAINTS) -e '$(1)'
endef

$(STAMP_DEMO): pyproject.toml $(CONSTRAINTS)
	$(call install,.)
	@touch $(STAMP_DEMO)

# '.[test]' holds '.': the demo's level is then installed too.
$(STAMP_TEST): pyproject.toml $(CONSTRAINTS)
	$(call install,.[test])
	@touch $(STAMP_TEST) $(STAMP_DEMO)

setup: $(STAMP_TEST)

demo: $(STAMP_DEMO)
	$(VENV)/bin/arroch demo

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# Two pytest-xdist workers, one per core (three made wall-clock bounds of mission tests miss). A
# test file stays on one worker, so the processes its module fixtures start are started once; files
# with slow tests go first (tests/conftest.py), so both workers end together. --no-loadscope-reorder
# (pytest-xdist 3.8) keeps that order: since 3.5 xdist hands out the files with the most tests first,
# which left the long single-test files (the study, the demo, the ROS 2 missions) to the last minutes.
TEST_WORKERS ?= 2

test: lint
	@.ci/system-packages
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

# '.[test]' holds '.[peers]': benchmarks/peers.py exits 2 without unified-planning's engines.
bench: $(STAMP_TEST)
	@mkdir -p benchmarks/results
	@for b in benchmarks/*.py; do \
		echo "== $$b" >&2; \
		$(PY) $$b > benchmarks/results/$$(basename $$b .py).json || exit 1; \
		cat benchmarks/results/$$(basename $$b .py).json; \
	done

# Every figure and number the docs quote, from a fresh demo run (docs/figures.json, docs/demo-timeline.png;
# the docs quote them and tests/test_docs_figures.py checks they match).
docs: $(STAMP_DEMO)
	$(PY) docs/make_docs.py

# A fresh venv with no constraints: pip picks the newest versions pyproject.toml allows; they are
# then tested (make test) and committed. Run it to move to newer releases on purpose.
constraints:
	rm -rf $(VENV)-constraints
	$(PYTHON) -m venv $(VENV)-constraints
	$(VENV)-constraints/bin/python -m pip install -qq --upgrade 'pip>=24,<27'
	$(VENV)-constraints/bin/python -m pip install -qq -e '.[test]'
	{ echo "# Versions CI installed for '.[test]' (Python $$($(VENV)-constraints/bin/python -c 'import platform; print(platform.python_version())'), Linux x86_64)."; \
	  echo "# Used by every install from the Makefile (pip -c). Regenerate with: make constraints"; \
	  $(VENV)-constraints/bin/python -m pip freeze --exclude-editable; } > $(CONSTRAINTS)
	rm -rf $(VENV)-constraints

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
