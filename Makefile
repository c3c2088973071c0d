# make demo        — set up .venv if missing, then run the main job on the default site
# make test        — set up .venv if missing, install the system packages tests need (when root),
#                    check lint and formatting (ruff), then run the whole test suite
# make bench       — set up .venv if missing, then run every benchmark (JSON on stdout, files in benchmarks/results/)
# make constraints — re-resolve every dependency to its newest allowed version and pin it in constraints.txt

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# The versions CI installed (see `make constraints`): every install from this Makefile uses them.
CONSTRAINTS := constraints.txt

.PHONY: setup demo test lint bench constraints clean

# -qq: pip still prints errors (and fails the make), but not setuptools' notice about editable
# installs nor a machine's pip-config notices, which would greet every first run.
$(STAMP): pyproject.toml $(CONSTRAINTS)
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "installing arroch and its dependencies into $(VENV) (versions from $(CONSTRAINTS); minutes the first time)"
	$(PY) -m pip install -qq --upgrade 'pip>=24,<27'
	$(PY) -m pip install -qq -c $(CONSTRAINTS) -e '.[test]'
	@touch $(STAMP)

setup: $(STAMP)

demo: setup
	$(VENV)/bin/arroch demo

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

test: lint
	@.ci/system-packages
	$(PY) -m pytest -q -p no:cacheprovider

bench: setup
	@mkdir -p benchmarks/results
	@for b in benchmarks/*.py; do \
		echo "== $$b" >&2; \
		$(PY) $$b > benchmarks/results/$$(basename $$b .py).json || exit 1; \
		cat benchmarks/results/$$(basename $$b .py).json; \
	done

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
