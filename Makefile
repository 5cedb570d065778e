# Quick start: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-full docs-test lint docs bench clean

# pip compiles each installed module to bytecode one file at a time (≈ 35 s of a 56-s install
# on 2 cores); compileall does it on every core and skips the packages' own test suites
# (21 + 15 s). A file it cannot compile only goes without its cache: its status is ignored.
$(STAMP): pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet --no-compile -e ".[dev]"
	$(BIN)/python -m compileall -q -j 0 -x '/tests?/' $(VENV)/lib > /dev/null || true
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hrgjax demo --out out/demo

# Two test files at a time on two cores (pytest-xdist; each file stays in one worker, so its
# module-scoped fixtures compile once), compiling with XLA's quick flags (tests/conftest.py):
# 11 min 10 s to 11 min 40 s on the 2-core machine (.ci/run on clean clones of c804c74 to
# abb8ca5 with the install, pytest 614–636 s, 2026-11-29; 12–15 ½ min earlier that day, before
# set-up functions compiled as one program each; before the flags ≈ 25 min, pytest 1 431 s);
# 5 min 7 s (pytest 282 s, 409b68d) that afternoon on a machine ≈ 2.2× faster.
# The tests marked `slow` and the heavy docs pages are left to test-full / docs-test. The 20 slowest tests are listed at the end,
# so every CI log shows where the time goes.
test: $(STAMP)
	@# hrgjax's bytecode once for every test process (where PYTHONDONTWRITEBYTECODE is set,
	@# each would compile the package again: ≈ 0.6 s a process)
	$(BIN)/python -m compileall -q -j 0 hrgjax > /dev/null || true
	$(BIN)/python -m pytest -q -n auto --dist loadfile --durations=20

# Everything: the fast tier above, the tests marked `slow` (whole studies, 20-100 s each, each
# naming the fast test that covers its behaviour) and every docs block at full size. Run it
# before a change to the physics lands, and on a GPU machine (benchmarks/on_gpu.sh).
test-full: $(STAMP)
	HRGJAX_TEST_FULL=1 HRGJAX_DOCS_FULL=1 $(BIN)/python -m pytest -q -n auto --dist loadfile --durations=20

# Every python block of docs/ at the size the page shows, the compile-bound ones included,
# with the fast tier's quick-compile flags (tests/conftest.py: the pages are compile-bound)
# (make test runs the light pages at reduced sizes, compiles the heavy pages' blocks as Python
# and lists the compile-bound ones as skipped). Run it before a change to docs/ lands.
docs-test: $(STAMP)
	HRGJAX_DOCS_FULL=1 $(BIN)/python -m pytest -q tests/test_docs_examples.py

lint: $(STAMP)
	$(BIN)/ruff check hrgjax tests benchmarks
	$(BIN)/ruff format --check hrgjax tests benchmarks

docs: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	$(BIN)/python docs/make_figures.py
	$(BIN)/mkdocs build --strict --site-dir out/site

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf out .pytest_cache site
