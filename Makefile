# Set-up and the two README commands: `make demo` (the main job) and `make test` (the test suite).
PYTHON ?= python3.12
VENV ?= .venv
BIN := $(VENV)/bin
export MUJOCO_GL ?= egl

.PHONY: install system-deps test test-fast demo lint

# FFmpeg's shared libraries let LeRobot decode videos with torchcodec; without them LeRobot prints a
# long traceback and falls back to PyAV. Installed with apt-get when we are root (a failure, e.g. offline,
# only warns), otherwise explained.
system-deps:
	@if ldconfig -p 2>/dev/null | grep -q libavcodec; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "Installing FFmpeg libraries (apt-get install ffmpeg)"; \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends ffmpeg >/dev/null) \
			|| echo "apt-get install ffmpeg failed: LeRobot will fall back to PyAV for video decoding."; \
	else \
		echo "FFmpeg libraries not found and not root: run 'sudo apt-get install ffmpeg' for torchcodec (PyAV works without)."; \
	fi

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q -U pip
	$(BIN)/python -m pip install -q -e ".[dev]"
	touch $@

install: system-deps $(VENV)/.installed

# The whole suite, slow end-to-end tests included; what CI runs. Measured on 2 cores: 6.6 minutes, 9 while
# other jobs shared the cores (the slow tests' commands run beside the others: tests/omnid_jobs.py).
test: install
	$(BIN)/python -m pytest -q

# Without the tests marked slow (about 3.5 minutes).
test-fast: install
	$(BIN)/python -m pytest -q -m "not slow"

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The main job; e.g. `make demo DEMO_ARGS="--profile gpu --device cuda"` on a GPU machine.
demo: install
	$(BIN)/omnid-demo $(DEMO_ARGS)
