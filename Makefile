# Talk2PC. Two set-up commands for a fresh machine: `make run` and `make test`.
# Both create .venv from the pinned requirements.lock on first use.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-lock
ARGS ?=
# pytest-xdist workers for `make test` (auto: one per CPU core; 0: everything in one process)
WORKERS ?= auto

.PHONY: install run test test-fast lint format bench screenshots lock clean

$(STAMP): requirements.lock
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.lock
	touch $(STAMP)

install: $(STAMP)

run: install  ## serve the app on the bundled defaults (http://127.0.0.1:8080)
	$(PY) launch.py $(ARGS)

test: install  ## the whole test suite, real-browser test included: a worker per core, then the tests that race a clock alone
	$(PY) -m pytest -n $(WORKERS) --dist loadfile -m "not serial" $(ARGS)
	$(PY) -m pytest -m serial $(ARGS) || test $$? -eq 5

test-fast: install  ## everything but the slow, browser and clock-racing tests
	$(PY) -m pytest -n $(WORKERS) --dist loadfile -m "not slow and not browser and not serial" $(ARGS)

lint: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: install
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

bench: install  ## regenerate docs/PERFORMANCE.md
	$(PY) -m bench.run_all

screenshots: install  ## re-make the README's pictures (docs/images) from the shipped checkpoints
	$(PY) -m app.screenshots $(ARGS)

lock:  ## re-pin the whole tree after editing requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet -r requirements.txt
	( echo '# Whole dependency tree, pinned (regenerate with `make lock` after changing requirements.txt).'; \
	  $(PY) -m pip freeze --exclude-editable ) > requirements.lock

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
