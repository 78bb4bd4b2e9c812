# Two commands do all set-up on a fresh machine with Python >= 3.10:
#   make train   -> venv, install, train PPO, evaluate against LQR, write policy + pictures
#   make test    -> venv, install with test extras, run the test suite
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
RUN    ?= runs/ppo_stance

.PHONY: train test bench evaluate clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch is pinned and installed first: an unpinned torch (via SB3, TorchRL) would pull a multi-GB CUDA
# build; the pin is repeated in the second install so that no resolution can replace it
TORCH := torch==2.13.0
$(VENV)/.installed-%: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet '$(TORCH)'
	$(BIN)/python -m pip install --quiet -e '.[$*]' '$(TORCH)'
	touch $@

# numba caches a compiled kernel under its own file's timestamp, not those of the kernels it inlines
# from other files: after any edit of the package, drop every cached kernel so that none is stale
$(VENV)/.numba-fresh: $(wildcard leg_env/*.py leg_env/envs/*.py) | $(BIN)/python
	find leg_env \( -name '*.nbi' -o -name '*.nbc' \) -delete
	touch $@

train: $(VENV)/.installed-train $(VENV)/.numba-fresh
	$(BIN)/python -m train.ppo --out $(RUN)
	$(BIN)/python -m train.evaluate $(RUN) --baseline lqr --episodes 20 --gif

test: $(VENV)/.installed-test $(VENV)/.numba-fresh
	$(BIN)/python -m pytest -q

bench: $(VENV)/.installed-bench $(VENV)/.numba-fresh
	$(BIN)/python benchmarks/bench_dynamics.py
	$(BIN)/python benchmarks/bench_env.py --ppo

clean:
	rm -rf $(VENV) runs .pytest_cache
