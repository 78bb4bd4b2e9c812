# Two commands do all set-up on a fresh machine with Python >= 3.10:
#   make train   -> venv, install, train plain PPO from scratch on the push task (PlanarLegPush-v2), evaluate it
#                   against the stepping controller and the LQR on the push curve, write the policy and its pictures
#   make test    -> venv, install with test extras, run the test suite; then a second venv with
#                   Ray RLlib (and the Gymnasium it pins) runs the suite minus SB3, plus tests/rllib/
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
RUN    ?= runs/ppo_push_v2
TORCH_THREADS ?= 2
RLLIB_VENV ?= .venv-rllib
RLLIB_BIN  := $(RLLIB_VENV)/bin
# pytest-xdist workers for `make test`: one per CPU this process may run on (its affinity, as a container
# or CI runner sets it); TEST_WORKERS=0 runs the tests in one process
TEST_WORKERS ?= $(shell $(PYTHON) -c "import os; print(len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count() or 1)")
PYTEST := -m pytest -q -n $(TEST_WORKERS)

.PHONY: train test test-rllib bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch is pinned and installed first: an unpinned torch (via SB3, TorchRL) would pull a multi-GB CUDA
# build; the pin is repeated in the second install so that no resolution can replace it
TORCH := torch==2.13.0
$(VENV)/.installed-%: pyproject.toml setup.py constraints.txt | $(BIN)/python
	$(BIN)/python -m pip install --quiet -c constraints.txt '$(TORCH)'
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[$*]' '$(TORCH)'
	touch $@

# the RLlib venv: ray[rllib] pins its own Gymnasium (1.2.2), so it cannot share the main venv
$(RLLIB_BIN)/python:
	$(PYTHON) -m venv $(RLLIB_VENV)
	$(RLLIB_BIN)/python -m pip install --quiet --upgrade pip

$(RLLIB_VENV)/.installed: pyproject.toml setup.py constraints.txt | $(RLLIB_BIN)/python
	$(RLLIB_BIN)/python -m pip install --quiet -c constraints.txt '$(TORCH)'
	$(RLLIB_BIN)/python -m pip install --quiet -c constraints.txt -e '.[rllib,test-core]' '$(TORCH)'
	touch $@

# The tests that need Stable-Baselines3, which the RLlib venv does not have, are chosen by where they sit and by
# their mark, never by name: tests/sb3/ (modules that need the training stack to be imported: ignored there) and
# the `sb3` mark (pyproject's markers; conftest.py puts it on every test of tests/sb3/), deselected there.
# A test that needs SB3 and has neither fails there with ModuleNotFoundError, it is never skipped;
# tests/test_suite_split.py checks the marks in the main venv.
RLLIB_TESTS := $(wildcard tests/rllib/test_*.py)

# the compiled core (leg_env/_core, C) is built in place by the editable install; after an edit of its
# sources it is built again (both venvs run the same Python, so they share the one built in place)
CORE_SOURCES := setup.py $(wildcard leg_env/_core/*.c leg_env/_core/*.h leg_env/_core/*.def)
$(VENV)/.core: $(CORE_SOURCES) | $(BIN)/python
	$(BIN)/python -m pip install --quiet --no-deps -e .
	touch $@

train: $(VENV)/.installed-train $(VENV)/.core
	$(BIN)/python -m train.ppo --env-id leg_env/PlanarLegPush-v2 --torch-threads $(TORCH_THREADS) --eval-freq 3000000 --eval-episodes 32 --eval-env-kwargs 'push_force:[50.0, 50.0]' --out $(RUN)
	$(BIN)/python -m train.evaluate $(RUN) --baseline stepping lqr --episodes 100 --push-curve --gif

test: $(VENV)/.installed-test $(VENV)/.core $(RLLIB_VENV)/.installed
	$(BIN)/python $(PYTEST)
	$(MAKE) --no-print-directory test-rllib

# the suite on RLlib's Gymnasium without SB3, and the RLlib tests (tests/rllib/, never collected by a
# plain `pytest`: pyproject's norecursedirs)
test-rllib: $(RLLIB_VENV)/.installed $(VENV)/.core
	$(RLLIB_BIN)/python $(PYTEST) --ignore=tests/sb3 -m "not sb3" tests $(RLLIB_TESTS)

bench: $(VENV)/.installed-bench $(VENV)/.core
	$(BIN)/python benchmarks/bench_dynamics.py
	$(BIN)/python benchmarks/bench_env.py --ppo

clean:
	rm -rf $(VENV) $(RLLIB_VENV) runs .pytest_cache build leg_env/_core/*.so
