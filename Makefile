# aveas-format — every target sets up what it needs (a .venv with the package) on a fresh machine.
# `make demo` installs the package with what the demo needs (the [demo] extra: MCAP and OSI
# exports, figures, pandas for the README's and the tutorials' Python); `make test` and the other
# targets install every extra and the test tools.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
DEMO_STAMP := $(VENV)/.installed-demo

.PHONY: demo test test-all bench docs fuzz clean

$(VENV)/.pip: 
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	touch $@

$(DEMO_STAMP): pyproject.toml | $(VENV)/.pip
	$(PY) -m pip install --quiet -e ".[demo]"
	touch $@

$(STAMP): pyproject.toml | $(VENV)/.pip
	$(PY) -m pip install --quiet -e ".[all,test]"
	# The official OpenDRIVE XSDs ship in asam-qc-opendrive, whose pins (numpy<2, lxml<6) clash
	# with ours; the tests only read its schema files, so it is installed without dependencies.
	$(PY) -m pip install --quiet --no-deps "asam-qc-opendrive==1.0.0"
	touch $@ $(DEMO_STAMP)

# writes demo-output/ (replacing the previous demo), ends with the HTML report and the figures
demo: $(DEMO_STAMP)
	$(VENV)/bin/aveas-format demo --output demo-output --overwrite

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow" -n auto

test-all: $(STAMP)
	HYPOTHESIS_PROFILE=explore $(PY) -m pytest -q -n auto

# a longer, randomised fuzzing campaign of the readers (make test replays a fixed, short one)
fuzz: $(STAMP)
	AVEAS_FUZZ_EXAMPLES=$${AVEAS_FUZZ_EXAMPLES:-2000} $(PY) -m pytest -q tests/security -x

bench: $(STAMP)
	$(PY) benchmarks/run.py

docs: $(STAMP)
	$(PY) tools/docgen.py
	$(PY) tools/docgen.py --tutorials
	$(PY) tools/docgen.py --figures

clean:
	rm -rf $(VENV) demo-output .pytest_cache .hypothesis build dist *.egg-info
