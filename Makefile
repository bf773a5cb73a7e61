# VoxGI — the two commands of the README (`make demo`, `make test`) set everything up from
# nothing: they create .venv and install requirements.txt when missing or changed; `make test`
# also installs what the browser tests need (web-deps).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements.installed
BLEND ?=
BENCH_ARGS ?=

WEB_STAMP := web/node_modules/.package-lock.installed

.PHONY: demo test lint build bench clean venv web-deps

$(STAMP): requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	cp requirements.txt $(STAMP)

venv: $(STAMP)

# The browser tests (tests/web, docs/web_reader.md): Debian's Chromium when /usr/bin/chromium is
# missing, and web/node_modules from web/package-lock.json (npm ci; Node.js from Debian if the
# machine has none) when missing or the lock changed. apt-get runs only when something is missing.
APT_INSTALL = SUDO=; [ "$$(id -u)" -eq 0 ] || SUDO=sudo; $$SUDO apt-get update -qq && \
	DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends

web-deps: $(WEB_STAMP)
	@test -x /usr/bin/chromium || { echo "web-deps: installing Debian's chromium" >&2; $(APT_INSTALL) chromium; }

$(WEB_STAMP): web/package-lock.json web/package.json
	@command -v npm >/dev/null || { echo "web-deps: installing Debian's nodejs, npm" >&2; $(APT_INSTALL) nodejs npm; }
	cd web && npm ci --no-audit --no-fund --loglevel=error
	cp web/package-lock.json $(WEB_STAMP)

demo: $(STAMP)
	$(PY) tools/demo.py $(if $(BLEND),--blend "$(BLEND)")

test: $(STAMP) web-deps
	$(PY) -m pytest -c tests/pytest.ini tests -q

lint: $(STAMP)
	$(VENV)/bin/ruff check .

build: $(STAMP)
	$(PY) tools/build_extension.py --output-dir dist

bench: $(STAMP) web-deps
	bash tools/bench/bench_setup.sh
	.venv-bench/bin/python tools/bench/bench.py $(BENCH_ARGS)

clean:
	rm -rf dist out .pytest_cache
