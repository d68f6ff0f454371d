# Two entry points for a fresh machine: `make run` and `make test`; `make test-fast` is the
# inner loop while developing (docs/development.md).
# Each creates .venv on first use and reinstalls only when pyproject.toml changes.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# Bytecode caches on, whatever the shell says: pytest keeps its assertion-rewritten test
# modules there, and collecting from a warm cache takes half the time (docs/development.md).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: run test test-fast lint bench clean browser

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

run: $(BIN)/.installed
	$(BIN)/deltadash serve

test: $(BIN)/.installed browser
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports
	$(BIN)/mypy kinematics hardware
	$(BIN)/pytest -q -n auto --maxprocesses=4 --dist loadgroup

# Lint and every test but the slow (> ~3 s: end-to-end runs, the wheel build) and browser ones.
test-fast: $(BIN)/.installed
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/pytest -q -n auto --maxprocesses=4 --dist loadgroup -m "not slow and not browser"

# The scene's browser test drives Debian's chromium (no browser download); if it cannot be
# installed here (not root, no apt) the test skips and says so.
browser:
	@command -v chromium >/dev/null || (apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) || \
		echo "warning: chromium could not be installed; the browser tests will skip"

bench: $(BIN)/.installed
	$(BIN)/python benchmarks/kinematics.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis .ruff_cache .mypy_cache
