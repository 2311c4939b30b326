.DEFAULT_GOAL := help
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARTIFACTS ?= artifacts
export MPLBACKEND := Agg
export PYVISTA_OFF_SCREEN := true

.PHONY: help venv test bench reproduce-paper studies report clean

help:
	@echo "make reproduce-paper  create .venv, run the publication's studies, write artifacts/report"
	@echo "make test             create .venv if needed and run the test suite"
	@echo "make bench            speed benchmarks (MSS kernels, static solver, FEM references)"
	@echo "make report           rebuild the report from stored results only"

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/hybmss bench
	$(BIN)/python -m benchmarks.run

studies: $(STAMP)
	$(BIN)/python -m studies run --all --out $(ARTIFACTS)/results

report: $(STAMP)
	$(BIN)/python -m reports build --results $(ARTIFACTS)/results --out $(ARTIFACTS)/report

reproduce-paper: $(STAMP)
	$(MAKE) studies
	$(MAKE) report

clean:
	rm -rf $(ARTIFACTS) .pytest_cache
