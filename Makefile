# rodphase: every target creates the environment it needs (.venv) on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
OUT    ?= out
JOBS   ?= 2

.PHONY: help install demo test lint bench figures phase fig3 onset-study clean

help:  ## list the targets
	@grep -hE '^[A-Za-z0-9 -]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

# constraints.txt pins the versions the documented numbers were measured with (pip freeze of
# a working install); `make install CONSTRAINTS=` installs the newest instead
CONSTRAINTS ?= constraints.txt

$(STAMP): pyproject.toml $(CONSTRAINTS)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev,dask]" $(if $(CONSTRAINTS),-c $(CONSTRAINTS))
	touch $(STAMP)

install: $(STAMP)  ## create .venv and install rodphase with its test and Dask extras

# `rodphase sweep` exits 1 when some runs failed (they are recorded); the demo goes on.
demo: $(STAMP)  ## run configs/quick.yaml (a small phase diagram) and draw its phase map
	@mkdir -p $(OUT)
	$(BIN)/rodphase sweep configs/quick.yaml -o $(OUT)/quick.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/rodphase classify $(OUT)/quick.h5 --csv $(OUT)/quick.csv
	$(BIN)/rodphase plot $(OUT)/quick.h5 --kind phase -o $(OUT)/quick_phase.png
	@echo "phase map: $(OUT)/quick_phase.png  data: $(OUT)/quick.h5  table: $(OUT)/quick.csv"

test: $(STAMP)  ## run the test suite
	$(BIN)/pytest -q

lint: $(STAMP)  ## static checks (ruff)
	$(BIN)/ruff check rodphase tests benchmarks studies

bench: $(STAMP)  ## kernel and topology benchmarks against PyElastica (installs the bench extra)
	$(BIN)/pip install --quiet -e ".[bench]"
	$(BIN)/python benchmarks/bench_kernel.py --write docs/benchmarks.md
	$(BIN)/python benchmarks/bench_topology.py

phase: $(STAMP)  ## Fig 3 in the stretched-rod reading of Phi*a (configs/fig3_stretched.yaml); fig3 is the paper's
	@mkdir -p $(OUT)
	$(BIN)/rodphase sweep configs/fig3_stretched.yaml -o $(OUT)/fig3_stretched.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/rodphase classify $(OUT)/fig3_stretched.h5 --csv $(OUT)/fig3_stretched.csv
	$(BIN)/rodphase plot $(OUT)/fig3_stretched.h5 --kind phase --twist current -o $(OUT)/fig3_stretched.png
	$(BIN)/python studies/critical_twist.py $(OUT)/fig3_stretched.csv --column phi_a_current --above 1.1

fig3: $(STAMP)  ## the paper's Fig 3: rest Phi*a = theta*a0/L0 against L/L0, with the Phi_c fit
	@mkdir -p $(OUT)
	$(BIN)/rodphase sweep configs/fig3_paper.yaml -o $(OUT)/fig3_paper.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/rodphase classify $(OUT)/fig3_paper.h5 --csv $(OUT)/fig3_paper.csv
	$(BIN)/rodphase plot $(OUT)/fig3_paper.h5 --kind phase -o $(OUT)/fig3_paper.png
	$(BIN)/python studies/critical_twist.py $(OUT)/fig3_paper.csv --above 1.1

figures: $(STAMP) fig3  ## every figure of the paper (see docs/reproduction.md)
	$(BIN)/python studies/figures.py --out $(OUT) --jobs $(JOBS)

onset-study: $(STAMP)  ## the straight rod's onset line under stiffer shear and G = E/3 (docs/reproduction.md)
	$(BIN)/python studies/onset_study.py --write

clean:  ## remove outputs (keeps .venv)
	rm -rf $(OUT) .pytest_cache

include studies/figures.mk
