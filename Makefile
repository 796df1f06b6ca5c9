# Two entry points (README quick start): `make demo` and `make test`.
# Both create and reuse a local virtual environment in .venv.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast lint bench bench-full docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	# the numba kernels compiled ahead into their disk cache: no command (nor every worker of an
	# audit at once) compiles them on first use
	$(BIN)/python -c "from dbtools.gis import match_kernel; from fieldlogs.simulate import radar; match_kernel.warm(); radar.warm()"
	# the project's own bytecode, as pip compiles an installed package's: an editable install
	# has none, and where bytecode is not written (PYTHONDONTWRITEBYTECODE) every command would
	# compile its ~150 modules from source (≈ 0.1–0.3 s of each `trainpos run`); a stale file
	# after an edit is ignored by Python, never wrong
	$(BIN)/python -m compileall -q cli dbtools fieldlogs schemas
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/trainpos demo --out demo-out

# the whole suite, as CI runs it: lint, types (mypy --strict), every test incl. the slow truth tests
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -q

# everyday work: lint and the tests without the slow statistical ones
test-fast: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q -m "not slow"

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# every benchmark at a quick size → the quick table of bench/RESULTS.md
bench: $(STAMP)
	OMP_NUM_THREADS=1 $(BIN)/python bench/run_all.py
	OMP_NUM_THREADS=1 $(BIN)/python bench/accuracy.py --runs 50

# the sizes the issues' targets are stated for → the full table of bench/RESULTS.md (the quick
# table kept as it is); the issues' figures hold for a quiet machine: run it at load < 1.5
bench-full: $(STAMP)
	OMP_NUM_THREADS=1 $(BIN)/python bench/run_all.py --full

# the user guide as a site (docs/ → site/, MkDocs; --strict: a dead link or anchor fails);
# regenerates the reference pages from the code first
docs: $(STAMP)
	$(BIN)/python -m cli.schema_docs
	$(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) site demo-out .pytest_cache .ruff_cache .hypothesis
