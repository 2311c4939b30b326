.DEFAULT_GOAL := help
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARTIFACTS ?= artifacts
export MPLBACKEND := Agg
export PYVISTA_OFF_SCREEN := true

.PHONY: help venv test test-fast bench reproduce-paper studies report clean

help:
	@echo "make reproduce-paper  create .venv, run the publication's studies (studies/data/studies/*.toml"
	@echo "                      and the extra studies' drivers), write artifacts/report"
	@echo "make test             create .venv if needed and run the test suite"
	@echo "make test-fast        the suite without the tests marked slow (day-to-day work)"
	@echo "make bench            speed benchmarks (explicit kernels, static solver, FEM references; asv suite)"
	@echo "make report           rebuild the report from stored results only"

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,engines]'
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --durations=40

test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow" --durations=10

# hybmss bench: f64 and f32 per-10k-step times of every model on 10³ and 30³, one and two threads,
# with the load average and the ratios of one run; then the asv suite once on the 10³ cube
# (`asv run --python=same` alone runs every mesh: 10³, 20³, 30³ and the beam).
bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[bench]'
	$(BIN)/hybmss bench
	$(BIN)/asv machine --yes > /dev/null
	HYBMSS_ASV_MESHES=10x10x10 $(BIN)/asv run --python=same --quick --show-stderr

# the runs of the experiment study files in studies/data/studies/ and of the extra studies
# (studies/paper/reproduce.py: STUDY_FILES, EXTRA_STUDIES), one resumable store
studies: $(STAMP)
	$(BIN)/python -m studies run --all --out $(ARTIFACTS)/results

report: $(STAMP)
	$(BIN)/python -m reports build --results $(ARTIFACTS)/results --out $(ARTIFACTS)/report

reproduce-paper: $(STAMP)
	$(MAKE) studies
	$(MAKE) report

clean:
	rm -rf $(ARTIFACTS) .pytest_cache
