# Two commands do everything on a fresh Debian/Ubuntu machine:
#   make render   set up (OpenCL, venv, package) and render the default scene to out/
#   make test     set up and run the test suite (every property; 4-5 minutes on 2 cores)
#   make test-full  the suite with its long campaigns, then the fuzzing campaign
#   make fuzz     the long fuzzing campaign (bench/fuzz.py; CASES=2000 SEED=0)
# Every step is idempotent: a second run only does what is missing.

VENV   ?= .venv
PYTHON ?= python3
PY     := $(VENV)/bin/python
SCENE  ?= scenes/cornell_box.toml

CASES  ?= 2000
SEED   ?= 0

# Tests run on every core (pytest-xdist); a file's tests stay on one worker,
# so that its module fixtures (engines, studies) are made once.
PYTEST := $(PY) -m pytest -q -n auto --dist loadfile

.PHONY: render test test-full bench fuzz setup opencl browser warm clean

render: setup $(VENV)/.warm
	$(VENV)/bin/oclgi render $(SCENE) -o out/$(basename $(notdir $(SCENE))).exr

test: setup browser
	$(PYTEST)

# The tests marked `full` too (README.md, Tests), then the fuzzing campaign.
test-full: setup browser $(VENV)/.warm
	$(PYTEST) --full
	$(PY) bench/fuzz.py --cases $(CASES) --seed $(SEED) -o out/fuzz

bench: setup browser $(VENV)/.bench
	$(PY) -m pytest bench -q --benchmark-json=bench/results/latest.json

# Generated inputs for every format and command, judged case by case: the
# summary table is printed and kept in out/fuzz/summary.md, a reproducer of
# each failure in out/fuzz/reproducers/ (tests/test_fuzz.py runs a small sample).
fuzz: setup $(VENV)/.warm
	$(PY) bench/fuzz.py --cases $(CASES) --seed $(SEED) -o out/fuzz

setup: $(VENV)/.installed opencl

# The package and its test extras, reinstalled when the metadata changes.
$(VENV)/.installed: setup.cfg pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

$(VENV)/.bench: $(VENV)/.installed
	$(PY) -m pip install -q -e '.[test,bench]'
	touch $@

# PoCL's kernel cache filled once per machine (oclgi warm), so that the first
# render does not spend seconds compiling; redone when a kernel changes. The
# tests compile cold in a private cache of their own and do not need it.
warm: $(VENV)/.warm
$(VENV)/.warm: $(VENV)/.installed $(wildcard kernels/*.cl kernels/*.h) | opencl
	$(VENV)/bin/oclgi warm
	touch $@

# Debian's PoCL when no OpenCL CPU device answers (never the PyPI PoCL wheel:
# its PoCL 3.0 fails on AVX-512 CPUs with "unknown target CPU 'generic'").
opencl: $(VENV)/.installed
	@sh tools/ensure-opencl.sh $(PY)

# Debian's chromium for the viewer's end-to-end test (headless, over the
# DevTools protocol; Playwright's own browsers are not downloaded).
browser:
	@sh tools/ensure-chromium.sh

clean:
	rm -rf $(VENV) out build *.egg-info
