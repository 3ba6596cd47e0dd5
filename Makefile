# live-performer: `make demo` runs the main job, `make test` runs the tests.
# Both set everything up first; `make setup` is a no-op in seconds when nothing changed.

PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
JIT_STAMP := $(VENV)/.jit-compiled
# System packages: PortAudio for live input, liblo-tools (oscdump) to prove the
# OSC wire format, mono-mcs to compile and run the Unity receiver's C# OSC parser
# against our encoder (tests/test_listen.py; about 20 s to install), espeak-ng for the
# synthetic speech the idle gate's presence detector learns and is tested on
# (models/training/music_gate.py, tests/test_music_gate.py), nats-server: the broker of
# `performer run --publish` (tests/test_publish.py, benchmarks/audience.py; docs/audience.md),
# pulseaudio, pulseaudio-utils and libasound2-plugins: a real live input for the tests (a private
# server's null sink captured through PortAudio's ALSA pulse device; realtime/pulse.py, tests/test_live_input.py).
APT_PKGS := libportaudio2 liblo-tools mono-mcs espeak-ng nats-server pulseaudio pulseaudio-utils libasound2-plugins

.PHONY: setup system-deps web browser-deps demo test test-fast bench soak constraints clean help

help:
	@echo "make demo   - set up, then run the main job on the bundled defaults"
	@echo "make test   - set up, then run the test suite"
	@echo "make setup  - create ./.venv and install the package (torch first)"
	@echo "make bench  - run the latency benchmark suite against benchmarks/budgets.toml"
	@echo "make soak   - SOAK_MINUTES (60) of audio through the full engine: no NaN, exact frames, flat RSS and fds"
	@echo "make constraints - re-pin constraints.txt to the newest releases (docs/install.md)"

setup: system-deps $(STAMP) $(JIT_STAMP) $(if $(shell command -v npm 2>/dev/null),web)

system-deps:
	@missing=""; for p in $(APT_PKGS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing system packages:$$missing"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing) >/dev/null \
	      || echo "warning: could not install$$missing; live audio input, oscdump, C# or broker tests will be skipped"; \
	  else echo "note: missing system packages:$$missing (live audio input / oscdump / C# / broker tests will be skipped)"; fi; \
	fi

# Every Python package at the exact version of constraints.txt (docs/install.md); torch
# first, so that nothing pulls a CUDA build.
$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --disable-pip-version-check -c constraints.txt torch==2.13.0
	$(BIN)/pip install -q --disable-pip-version-check -c constraints.txt -e '.[dev]'
	touch $(STAMP)

# The live path's numba kernels, compiled once into __pycache__ (realtime/kernels.py) so that
# the first `performer run` loads them instead of compiling them inside its warm-up.
$(JIT_STAMP): $(STAMP) realtime/kernels.py models/features/spectral.py models/features/context.py \
		models/networks/dance_jit.py realtime/pose_jit.py
	$(BIN)/python -m realtime.kernels
	touch $(JIT_STAMP)

# make constraints: resolve pyproject.toml's dependencies afresh (newest releases) in a
# scratch venv and write their exact versions to constraints.txt, keeping its header.
# Review `git diff constraints.txt`, then `make test` (docs/install.md).
LOCK_VENV ?= /tmp/live-performer-constraints
constraints:
	rm -rf $(LOCK_VENV) && $(PY) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/pip install -q --disable-pip-version-check torch==2.13.0
	$(LOCK_VENV)/bin/pip install -q --disable-pip-version-check -e '.[dev]'
	{ sed -n '/^#/p' constraints.txt; $(LOCK_VENV)/bin/pip freeze | grep -v '^-e \|^#' \
	  | sed 's/^torch==\([^+]*\)+.*/torch==\1/'; } > constraints.txt.new
	mv constraints.txt.new constraints.txt
	rm -rf $(LOCK_VENV)
	@if git diff --quiet constraints.txt 2>/dev/null; then echo "constraints.txt: no version changed"; else git diff --stat constraints.txt; fi

# Web viewer (docs/receivers.md): clients/web/dist is committed, so the viewer works
# without npm. With npm, `make web` rebuilds dist/ when a source differs from the build
# (a hash of the sources is kept in dist/.source-hash): nothing to do in well under a second.
WEB      := clients/web
WEB_SRC   = $(WEB)/package.json $(WEB)/package-lock.json $(WEB)/index.html $(WEB)/vite.config.js $(sort $(wildcard $(WEB)/src/*.js $(WEB)/public/*))
WEB_HASH  = $(shell cat $(WEB_SRC) | sha256sum | cut -c1-16)
web:
	@if [ "$$(cat $(WEB)/dist/.source-hash 2>/dev/null)" != "$(WEB_HASH)" ]; then \
	  echo "building the web viewer into $(WEB)/dist"; \
	  cd $(WEB) && { [ node_modules/.package-lock.json -nt package-lock.json ] || npm ci --no-audit --no-fund; } \
	    && npm run build && echo "$(WEB_HASH)" > dist/.source-hash; \
	fi

# Debian's chromium for the browser tests (tests/test_web_client.py skips without it).
browser-deps:
	@if ! dpkg -s chromium >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing chromium for the web viewer tests"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null \
	      || echo "warning: could not install chromium; the browser tests will be skipped"; \
	  else echo "note: chromium is not installed; the browser tests will be skipped"; fi; \
	fi

# The bundled clip through the default checkpoint in real time, looped for
# DEMO_SECONDS of audio: VMC over OSC to 127.0.0.1:39539, WebSocket + web viewer
# on http://127.0.0.1:8765/ (the URL is printed). Ctrl-C stops it.
DEMO_SECONDS ?= 120
demo: setup
	$(BIN)/performer run --audio models/assets/clip.ogg --loop --duration $(DEMO_SECONDS)

# Two passes (docs/testing.md): every test not marked `serial` on both cores (pytest-xdist, one
# worker per core, a test file per worker at a time), then the `serial` ones alone, which time
# themselves against the wall clock or pin CPUs. The exit status fails if either pass fails
# (nothing is printed after the serial pass's summary line unless one did).
TEST_PARALLEL := -n 2 --dist loadfile
test: setup browser-deps
	@$(BIN)/python -m pytest -q $(TEST_PARALLEL) -m "not serial" --durations=25; p=$$?; \
	$(BIN)/python -m pytest -q -m serial --durations=25; s=$$?; \
	[ $$p = 0 ] && [ $$s = 0 ] || { echo "make test: parallel pass exit $$p, serial pass exit $$s" >&2; exit 1; }

test-fast: setup browser-deps
	@$(BIN)/python -m pytest -q $(TEST_PARALLEL) -m "not slow and not serial"; p=$$?; \
	$(BIN)/python -m pytest -q -m "serial and not slow"; s=$$?; [ $$p = 0 ] && [ $$s = 0 ]

# make bench: the latency suite (docs/latency.md) on the bundled clip and BENCH_SONGS from
# DATA, the concurrency sweep, the ensemble (1, 2, 4, 8 performers in one process against
# as many processes, on the clip), then every result against benchmarks/budgets.toml (exit 1
# with a diff when over). Every process is pinned to BENCH_CORES (set it empty not to pin).
DATA        ?= ../shared/data/dwm
BENCH_OUT   ?= out/bench
BENCH_CORES ?= 0,1
BENCH_SONGS ?= DANCE_C_2 DANCE_W_1
BENCH_PIN   := $(if $(BENCH_CORES),--cores $(BENCH_CORES))

bench: setup
	rm -rf $(BENCH_OUT) && mkdir -p $(BENCH_OUT)
	$(BIN)/performer bench latency $(BENCH_PIN) --label clip --out $(BENCH_OUT)/clip
	@songs=""; for s in $(BENCH_SONGS); do f="$(DATA)/$$s/audio.mp3"; \
	  if [ -f "$$f" ]; then songs="$$songs --audio $$f"; \
	    echo "$(BIN)/performer bench latency $(BENCH_PIN) --audio $$f --label $$s --out $(BENCH_OUT)/$$s"; \
	    $(BIN)/performer bench latency $(BENCH_PIN) --audio "$$f" --label $$s --out $(BENCH_OUT)/$$s || exit 2; \
	  else echo "make bench: $$f not found (set DATA=...); skipping $$s"; fi; done; \
	echo "$(BIN)/performer bench streams $(BENCH_PIN) --audio models/assets/clip.ogg $$songs --out $(BENCH_OUT)/streams"; \
	$(BIN)/performer bench streams $(BENCH_PIN) --audio models/assets/clip.ogg $$songs --out $(BENCH_OUT)/streams || exit 2
	$(BIN)/performer bench ensemble $(BENCH_PIN) --out $(BENCH_OUT)/ensemble
	$(BIN)/performer bench check --budgets benchmarks/budgets.toml --summary $(BENCH_OUT)/summary.md $(BENCH_OUT)

# make soak: docs/reliability.md. Exit 1 if a check fails; figures in $(SOAK_OUT). SOAK_ARGS: more
# benchmarks/soak.py options, e.g. the stability check on songs looped:
#   make soak SOAK_ARGS="--data $(DATA) --cache .cache/corpus --songs DANCE_C_2 DANCE_R_5 DANCE_W_5"
SOAK_MINUTES ?= 60
SOAK_OUT     ?= out/soak.json
SOAK_ARGS    ?=
soak: setup
	mkdir -p $(dir $(SOAK_OUT))
	$(BIN)/python benchmarks/soak.py --minutes $(SOAK_MINUTES) --json $(SOAK_OUT) $(SOAK_ARGS)

clean:
	rm -rf $(VENV) *.egg-info .pytest_cache
