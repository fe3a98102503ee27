# Everything the project needs, built into .venv at the repo root.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
# The CPU build of torch 2.13.0 lies in /opt/wheels on these machines; elsewhere pip finds it on PyPI.
WHEELS := $(if $(wildcard /opt/wheels),--find-links /opt/wheels,)
STAMP  := $(VENV)/.installed

.PHONY: setup browser demo test test-fast corpus results-foundation bench screenshots serve clean

setup: $(STAMP) browser

# Browser tests drive Debian's chromium (Playwright never downloads a browser here).
browser:
	@command -v chromium >/dev/null || { \
	  echo "installing Debian's chromium for the browser tests"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	  || { echo "could not install chromium (needs root and Debian's packages)"; exit 1; }; }

$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --disable-pip-version-check $(WHEELS) -c requirements.lock -e '.[dev]'
	touch $(STAMP)

demo: setup            ## the main job on embedded defaults
	$(BIN)/nl2policy run --domain taxi

# Two pytest workers (pytest-xdist): much of the suite waits on subprocesses, servers and locks,
# so two cores run it in about two thirds of the time; tests that start Ray share one worker.
XDIST := -n 2 --dist loadgroup

test: setup            ## the whole test suite (CI runs this): under 10 minutes on 2 cores
	$(BIN)/python -m pytest $(XDIST)

test-fast: $(STAMP)    ## the tests that are neither slow, nor in a browser, nor training: under 2 minutes
	$(BIN)/python -m pytest $(XDIST) -m "not slow and not browser and not train"

corpus:                ## refresh the shipped corpus copy from ../shared/corpus
	cp ../shared/corpus/README.md ../shared/corpus/BRIEFING.md ../shared/corpus/vocabulary.json \
	   ../shared/corpus/taxi.jsonl ../shared/corpus/highway.jsonl src/nl2policy/data/corpus/
	mkdir -p src/nl2policy/data/corpus/round2
	cp ../shared/corpus/round2/README.md ../shared/corpus/round2/taxi.jsonl ../shared/corpus/round2/highway.jsonl \
	   src/nl2policy/data/corpus/round2/

results-foundation: setup   ## results/foundation/tree_returns.md
	$(BIN)/python -m experiments.policy corpus-returns --domain taxi --screen-episodes 100 --episodes 2000 --seed 0 --out results/foundation
	$(BIN)/python -m experiments.policy corpus-returns --domain highway --screen-episodes 10 --episodes 100 --seed 0 --out results/foundation

serve: setup          ## the web app on http://127.0.0.1:8000/
	$(BIN)/nl2policy serve

screenshots: setup    ## docs/*.png, one per page, taken by the browser test
	NL2POLICY_SCREENSHOTS=docs $(BIN)/python -m pytest tests/test_browser.py

bench: setup
	$(BIN)/python benchmarks/env_steps.py

clean:
	rm -rf $(VENV) build src/*.egg-info
