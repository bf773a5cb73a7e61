# VoxGI — the two commands of the README (`make demo`, `make test`) set everything up from
# nothing: they create .venv and install requirements.txt when missing or changed.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements.installed
BLEND ?=
BENCH_ARGS ?=

.PHONY: demo test lint build bench clean venv

$(STAMP): requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	cp requirements.txt $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) tools/demo.py $(if $(BLEND),--blend "$(BLEND)")

test: $(STAMP)
	$(PY) -m pytest -c tests/pytest.ini tests -q

lint: $(STAMP)
	$(VENV)/bin/ruff check .

build: $(STAMP)
	$(PY) tools/build_extension.py --output-dir dist

bench: $(STAMP)
	bash tools/bench/bench_setup.sh
	.venv-bench/bin/python tools/bench/bench.py $(BENCH_ARGS)

clean:
	rm -rf dist out .pytest_cache
