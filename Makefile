# objslam: `make demo` sets up and builds a map of the bundled bag; `make test` sets
# up and runs every test and the linter. Both are quick no-ops for what is already set up.
SHELL := /bin/bash
.DEFAULT_GOAL := help
RUN := source env.sh &&

.PHONY: help setup demo test lint clean

help:
	@echo "make demo   set up (if needed) and build the map of bags/office"
	@echo "make test   set up (if needed), lint and type-check, and run the whole test suite"
	@echo "make setup  only set up .venv and the colcon workspace"

setup:
	@scripts/setup.sh

demo: setup
	@$(RUN) scripts/demo.sh

lint: setup
	@$(RUN) ruff check src tests scripts && ruff format --check src tests scripts && mypy

# One pytest-xdist worker more than the cores (at most 4): many tests wait on subprocesses,
# ROS discovery and bag playback, and a spare worker fills those waits.
WORKERS = $(shell python3 -c 'import os; print(min(4, len(os.sched_getaffinity(0)) + 1))')

test: lint
	@$(RUN) python -m pytest -n $(WORKERS)

clean:
	rm -rf build install log .venv
