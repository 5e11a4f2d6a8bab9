# Two commands for a newcomer: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
export MPLBACKEND := Agg

.PHONY: install test test-all demo bench docs clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist worksteal  # two workers; an idle one takes tests from the busy one

# every test, the slow concealed-campaign diagnoses (marker `slow`) included: about 8 minutes more
test-all: $(STAMP)
	$(PY) -m pytest -q -n 2 --dist worksteal -m "slow or not slow"

demo: $(STAMP)
	$(PY) -m motorid demo

# the docs/ pages as a site in build/site (git-ignored); mkdocs comes from the optional extra `docs`
DOCS_STAMP := $(VENV)/.docs-stamp
$(DOCS_STAMP): pyproject.toml $(STAMP)
	$(PY) -m pip install -q -e '.[test,docs]'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/mkdocs build --strict --quiet
	@echo "docs built: build/site/index.html"

bench: $(STAMP)
	$(PY) -m compileall -q motorid  # byte-code on disk, as a normal install has it, even under PYTHONDONTWRITEBYTECODE
	$(PY) -m pytest -q -n 2 -m slow  # the slow tests `make test` leaves out
	$(PY) benchmarks/run.py

clean:
	rm -rf $(VENV) build *.egg-info
