# Two commands do all the set-up: `make demo` and `make test`.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
PIP_FLAGS := --disable-pip-version-check -q
# every extra the test suite exercises (ray backend, mp4, docs build, TorchRL/BenchMARL/RLlib)
TEST_EXTRAS := dev,train,ray,video,docs,torchrl,benchmarl,rllib

.PHONY: demo test test-all lint format bench docs clean

$(BIN)/python:
	$(PY) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml constraints.txt
	$(BIN)/python -m pip install $(PIP_FLAGS) --upgrade pip
	$(BIN)/python -m pip install $(PIP_FLAGS) -c constraints.txt -e ".[$(TEST_EXTRAS)]"
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

# the API reference is built from the docstrings (mkdocstrings); warnings are errors
docs: $(STAMP)
	$(BIN)/python -m mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) demo_out .pytest_cache site
