# bagtools: `make demo` sets up and runs the main job; `make test` sets up and runs the tests;
# `make docs` regenerates the lab guide's outputs, figures and tables (docs/lab.md).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
BAGTOOLS := $(VENV)/bin/bagtools
OUT    ?= out

.PHONY: setup sysdeps demo test docs bench fixtures clean

# System library Open3D loads at import time (libusb-1.0). Installed with apt-get when
# we may; otherwise the one command that does it is printed and setup stops.
sysdeps:
	@if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  echo "installing libusb-1.0-0 (needed by Open3D)"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	elif command -v sudo >/dev/null && command -v apt-get >/dev/null && sudo -n true 2>/dev/null; then \
	  sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	else \
	  echo "Open3D needs libusb-1.0. Install it with: sudo apt-get install libusb-1.0-0  (macOS: brew install libusb)"; exit 2; \
	fi

$(VENV)/.installed: pyproject.toml
	@echo "setting up $(VENV): a virtual environment with bagtools and its dependencies (a few minutes the first time)"
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -e '.[test]'
	touch $@

setup: sysdeps $(VENV)/.installed

demo: setup
	$(BAGTOOLS) simulate $(OUT)/turtlebot3_sim --force
	$(BAGTOOLS) info $(OUT)/turtlebot3_sim
	$(BAGTOOLS) map-cloud $(OUT)/turtlebot3_sim --out $(OUT)/cloud_map --voxel 0.02 --sample 0.2 --force
	$(BAGTOOLS) map-cloud $(OUT)/turtlebot3_sim --out $(OUT)/cloud_map_odom --frame odom --voxel 0.02 --sample 0.2 --force
	$(BAGTOOLS) ndt-odom $(OUT)/turtlebot3_sim --out $(OUT)/ndt_odom --force
	$(BAGTOOLS) grid $(OUT)/turtlebot3_sim --out $(OUT)/grid --force
	$(BAGTOOLS) grid $(OUT)/turtlebot3_sim --out $(OUT)/grid_ndt --poses $(OUT)/ndt_odom/trajectory.tum --frame odom --force
	@echo "demo outputs are under $(OUT)/"

# One pytest worker per core (pytest-xdist): the slowest tests replay real logs for tens of seconds each.
# OpenBLAS on one thread in each worker, as the CLI runs it: 623 -> 528 CPU s and 329 -> 286 s here.
test: setup
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n auto

docs: setup
	$(PY) docs/make_figures.py

bench: setup
	$(PY) -m pip install -q -e '.[test,bench]'
	$(PY) -m bench

fixtures: setup
	$(PY) -m fixtures.generate

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info
