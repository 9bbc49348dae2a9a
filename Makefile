# Two commands do everything on a fresh machine:
#   make demo   - create .venv, install abb-gym alone (no torch, no Ray), run the main
#                 demonstration (figures in out/demo)
#   make test   - create .venv, install abb-gym with its training and test extras (SB3, CPU
#                 torch, Ray), run the default test suite
# Long runs (training, sweeps, random fuzzing, repeats) are opt-in: make test-slow, make bench,
# make fuzz, make repeat N=20.  make docs builds the documentation site (docs/, strict).
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
# torch is pinned to the CPU wheel on disk: an unpinned torch pulls several GB of CUDA packages.
# An editable install of a package whose data folders map into it (pyproject.toml: package-dir)
# goes through setuptools' import finder, which prints a 10-line notice on every install; only
# that notice is silenced, every other warning of the build still shows
PIP_INSTALL := PYTHONWARNINGS="ignore:Editable installation" $(PIP) install -q -c constraints.txt

.PHONY: setup demo test test-slow fuzz repeat bench kernels wheel docs clean

setup: $(VENV)/.installed

$(VENV)/.created:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	touch $@

# the demo needs the package and its core dependencies only
$(VENV)/.installed-core: $(VENV)/.created pyproject.toml constraints.txt
	$(PIP_INSTALL) -e .
	touch $@

$(VENV)/.installed: $(VENV)/.created pyproject.toml constraints.txt
	$(PIP_INSTALL) -e ".[train,test]"
	touch $@

$(VENV)/.installed-docs: $(VENV)/.installed
	$(PIP_INSTALL) -e ".[docs]"
	touch $@

demo: $(VENV)/.installed-core
	$(PY) -m abb_gym.cli demo --out out/demo

# the test files in TEST_WORKERS processes (pytest-xdist; a file's tests stay together, so a
# module's fixtures run once): on this 2-core machine a fresh clone's run takes 8 minutes
# instead of 12, most of it numba compiling kernels, which one process does on one core.
# TEST_WORKERS=0 runs everything in one process
TEST_WORKERS ?= 2
XDIST := $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile)

test: setup
	$(PY) -m pytest -q --runwheel $(XDIST)

test-slow: setup
	$(PY) -m pytest -q --runslow

# the property-based suites with 20x the examples, new random ones each run (the default test
# run draws the same examples every time: tests/conftest.py)
fuzz: setup
	ABB_GYM_FUZZ_SCALE=20 $(PY) -m pytest -q tests/test_bad_input.py tests/test_make_inputs.py \
		tests/test_cli_inputs.py tests/test_env_inputs.py tests/test_agent_files.py

# make test's test run N times in a row, stopping at the first failure (a flakiness hunt; run
# it in two clones at once and each is the other's load)
N ?= 20
repeat: setup
	for i in $$(seq 1 $(N)); do echo "run $$i of $(N)"; \
		$(PY) -m pytest -q -p no:cacheprovider --runwheel $(XDIST) || exit 1; done

bench: setup
	$(PY) -m abb_gym.cli bench speed

# compile the kernels ahead of time (abb_gym.kernels), then build a wheel that ships them
kernels: setup
	$(PY) -m abb_gym.cli build-kernels

wheel: kernels
	$(PY) -m pip wheel . --no-deps -q -w dist

# the site in docs/_build/html, from the sources: -W fails on any warning (a docstring that does
# not parse, a cross-reference or a link of the built site that resolves to nothing: see
# docs/_ext/site_check.py), --keep-going lists them all first; -E reads every page again
docs: $(VENV)/.installed-docs
	$(PY) -m sphinx -b html -W --keep-going -E -q docs docs/_build/html

clean:
	rm -rf $(VENV) out docs/_build docs/api/abb_gym*.rst
	find abb_gym -name '*.nbi' -delete -o -name '*.nbc' -delete
	rm -f abb_gym/_kernels/numba-sources.sha1
