# Two commands do all the set-up: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
PIP_FLAGS := --disable-pip-version-check -q

.PHONY: demo test test-all lint format bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml constraints.txt
	$(BIN)/python -m pip install $(PIP_FLAGS) --upgrade pip
	$(BIN)/python -m pip install $(PIP_FLAGS) -c constraints.txt -e ".[dev,train]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m fov_marl.demo --out demo_out

test: $(STAMP)
	$(BIN)/python -m pytest -n auto -q

test-all: $(STAMP)
	$(BIN)/python -m pytest -n auto -q -m "slow or not slow"

lint: $(STAMP)
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format . && $(BIN)/ruff check --fix .

bench: $(STAMP)
	$(BIN)/fov-marl bench

clean:
	rm -rf $(VENV) demo_out .pytest_cache
