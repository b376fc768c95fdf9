# Two commands on a fresh Debian 12 machine:  `make demo`  and  `make test`.
# Both install what they need: Debian's libllvm19 (Mitsuba's CPU backend; Debian's default
# LLVM 14/15 crash Dr.Jit 1.5) and povray, a venv with torch 2.13.0 (CPU wheel) first, then sasmi.
SHELL := /bin/bash
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.sasmi-installed
DEBS := libllvm19 povray
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: setup demo test bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	@missing=$$(for p in $(DEBS); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages: $$missing"; \
	  $(SUDO) apt-get update -q && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -q --no-install-recommends $$missing; \
	fi
	python3 -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -e '.[test]'
	touch $@

# the main job on the shipped weights, no real chip needed: 16 renders, the same scenes made realistic
# (shipped generator, floors drawn from the shipped seabeds), their labels as COCO, one sheet of all three
demo: setup
	rm -rf demo  # redrawn whole, so a changed preset never meets an old demo's settings
	$(BIN)/sasmi render scenes/cylinder_chip.toml --count 16 --size 128 --out demo/renders
	$(BIN)/sasmi generate scenes/cylinder_chip.toml --count 16 --out demo/chips
	$(BIN)/sasmi export demo/chips --format coco --out demo/chips_coco.json
	$(BIN)/sasmi sheet demo/renders demo/chips --out demo/contact_sheet.png
	@echo "demo: render | realistic chip | its mask outline in demo/contact_sheet.png; COCO labels in demo/chips_coco.json"

# test files on up to 4 workers (pytest-xdist; 2 on a 2-core machine), each file on one worker
test: setup
	$(BIN)/pytest -q -n auto --maxprocesses 4 --dist loadfile

bench: setup
	$(BIN)/python benchmarks/render.py

clean:
	rm -rf $(VENV) demo
