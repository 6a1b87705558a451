# aveas-format — every target sets up what it needs (a .venv with the package) on a fresh machine.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-all bench docs fuzz clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	# The official OpenDRIVE XSDs ship in asam-qc-opendrive, whose pins (numpy<2, lxml<6) clash
	# with ours; the tests only read its schema files, so it is installed without dependencies.
	$(PY) -m pip install --quiet --no-deps "asam-qc-opendrive==1.0.0"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/aveas-format demo --output demo-output

test: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

test-all: $(STAMP)
	$(PY) -m pytest -q

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
