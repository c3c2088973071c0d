# make demo  — set up .venv if missing, then run the main job on the default site
# make test  — set up .venv if missing, then run the whole test suite
# make bench — set up .venv if missing, then run every benchmark (JSON on stdout, files in benchmarks/results/)

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup demo test bench clean

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

setup: $(STAMP)

demo: setup
	$(VENV)/bin/arroch demo

test: setup
	$(PY) -m pytest -q -p no:cacheprovider

bench: setup
	@mkdir -p benchmarks/results
	@for b in benchmarks/*.py; do \
		echo "== $$b" >&2; \
		$(PY) $$b > benchmarks/results/$$(basename $$b .py).json || exit 1; \
		cat benchmarks/results/$$(basename $$b .py).json; \
	done

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
