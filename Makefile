VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install test demo bench clean reference

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e '.[dev,bench,ray,medkit]'
	touch $(STAMP)

test: install
	$(PY) -m pytest -n 2 tests

reference: install
	$(PY) scripts/gen_reference.py

demo: install
	bash scripts/demo.sh

clean:
	rm -rf $(VENV) .pytest_cache
