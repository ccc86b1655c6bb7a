# rodphase: every target creates the environment it needs (.venv) on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
OUT    ?= out
JOBS   ?= 2

.PHONY: help install demo test test-slow test-all lint clean docs docs-serve

##@ Use
help:  ## list the targets
	@awk -F':.*## ' '/^##@ / {printf "%s%s\n", (headings++ ? "\n" : ""), substr($$0, 5); next} \
		/^[A-Za-z0-9 -]+:.*## / {if (length($$1) > 20) printf "  make %s\n  %-25s %s\n", $$1, "", $$2; \
		else printf "  make %-20s %s\n", $$1, $$2}' $(MAKEFILE_LIST)

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

# Two tiers (pyproject.toml's `slow` marker): `make test` runs the tests that guard what a user
# runs, on every core (pytest-xdist; tests/conftest.py compiles the kernel once before the
# workers start); the long tier holds the long physics checks, the robustness corpus, the
# fresh-compile test and the studies' smoke tests. tests/test_tiers.py checks that the two
# together run every test once.
test: $(STAMP)  ## the tests that guard what a user runs, on all cores (a few minutes)
	$(BIN)/pytest -q -n auto -m "not slow"

test-slow: $(STAMP)  ## the long tier alone: what `make test` leaves out
	$(BIN)/pytest -q -n auto -m slow

test-all: test test-slow  ## every test: `make test`, then the long tier (what CI runs)

lint: $(STAMP)  ## static checks (ruff)
	$(BIN)/ruff check rodphase tests benchmarks studies

DOCS_STAMP = $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP) pyproject.toml $(CONSTRAINTS)
	$(BIN)/pip install --quiet -e ".[docs]" $(if $(CONSTRAINTS),-c $(CONSTRAINTS))
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)  ## build the docs site into out/site (strict: a warning or a broken link fails)
	NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(BIN)/mkdocs build --strict --quiet

docs-serve: $(DOCS_STAMP)  ## serve the docs at http://127.0.0.1:8000, rebuilt on every edit
	NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(BIN)/mkdocs serve

clean:  ## remove outputs (keeps .venv)
	rm -rf $(OUT) .pytest_cache

##@ Benchmarks (benchmarks/; the timings depend on the machine and its load: docs/explanation/performance.md)
# `make bench` is the four that docs/history/benchmarks.md reports; each script also has its own target.
.PHONY: bench bench-extra bench-kernel bench-topology bench-map bench-compile bench-overhead \
	current-fig3 bench-interleaved bench-laws bench-step-parts bench-work-precision bench-map-methods bench-lines bench-map-tolerance \
	bit-identical base-tree
BASE ?= main
BASE_TREE = $(OUT)/base-rodphase

bench: bench-kernel bench-topology bench-map bench-compile  ## kernel and topology against PyElastica, Fig 3 map time, compile time (installs the bench extra)

bench-extra: $(STAMP)
	$(BIN)/pip install --quiet -e ".[bench]"

bench-kernel: bench-extra  ## µs per step against PyElastica 1.0, into docs/history/benchmarks.md
	$(BIN)/python benchmarks/bench_kernel.py --write docs/history/benchmarks.md

bench-topology: bench-extra  ## link, twist and writhe per frame against PyElastica's knot_theory
	$(BIN)/python benchmarks/bench_topology.py

bench-map: $(STAMP)  ## Fig 3's sweep timed, labels against a finer reference, per-scene savings (docs/)
	$(BIN)/python benchmarks/phase_timing.py savings --write docs/history/performance.md
	$(BIN)/python benchmarks/phase_timing.py reference --samples 40
	$(BIN)/python benchmarks/phase_timing.py timing
	$(BIN)/python benchmarks/phase_timing.py compare --write docs/history/performance.md --write docs/history/benchmarks.md

bench-compile: $(STAMP)  ## first compile on an empty numba cache: make demo's steps, then per function
	$(BIN)/python benchmarks/compile_time.py demo --jobs $(JOBS)
	$(BIN)/python benchmarks/compile_time.py functions

current-fig3: $(STAMP)  ## Fig 3 as it ships: time, labels, fit into docs/current.json, the map into docs/img
	$(BIN)/python benchmarks/current_fig3.py --jobs $(JOBS)

bench-overhead: $(STAMP)  ## what a stored run costs beyond its simulation (2,000 tiny runs)
	$(BIN)/python benchmarks/bench_overhead.py --jobs $(JOBS)

# BASE's rodphase (a branch, tag or commit; default main), extracted for a before/after check
base-tree:
	rm -rf $(BASE_TREE) && mkdir -p $(BASE_TREE)
	git archive $(BASE) rodphase | tar -x -C $(BASE_TREE)

bench-interleaved: $(STAMP) base-tree  ## kernel CPU µs/step of BASE (default main) and this tree, interleaved
	$(BIN)/python benchmarks/bench_interleaved.py $(abspath $(BASE_TREE)) $(CURDIR)

bench-laws: $(STAMP)  ## µs per step of the paper's law and the neo-Hookean one, interleaved
	$(BIN)/python benchmarks/bench_laws.py

bench-step-parts: $(STAMP)  ## where a Fig 3 step goes; what a Newton iteration would cost (docs/history/performance.md)
	$(BIN)/python benchmarks/step_parts.py --write docs/history/performance.md

bench-work-precision: $(STAMP)  ## error against CPU time over n and dt (docs/history/performance.md, ~7 min)
	$(BIN)/python benchmarks/work_precision.py --write docs/history/performance.md

bench-lines: $(STAMP)  ## Fig 3 as lines against the maps of dots: wall (interleaved), two fine references, work against precision (~45 min)
	$(BIN)/python benchmarks/boundary_methods.py timing --pairs 3 --record
	@test -f out/perf/boundary_reference_paper_rate.csv || $(BIN)/python benchmarks/boundary_methods.py reference
	@test -f out/perf/boundary_reference_half_rate.csv || $(BIN)/python benchmarks/boundary_methods.py reference --reference half_rate
	$(BIN)/python benchmarks/boundary_methods.py compare --write
	$(BIN)/python benchmarks/boundary_methods.py protocols --write

bench-map-methods: $(STAMP)  ## Fig 3 independent vs along paths: CPU, wall, boundary error against a fine reference (~35 min)
	@test -f out/perf/map_reference.h5 || $(BIN)/python benchmarks/map_methods.py reference
	$(BIN)/python benchmarks/map_methods.py compare --rounds 2 --write

bench-map-tolerance: $(STAMP)  ## Fig 3 both samplers at hold tolerance 1e-3 and 3e-3 against the fine reference (~25 min)
	@test -f out/perf/map_reference.h5 || $(BIN)/python benchmarks/map_methods.py reference
	$(BIN)/python benchmarks/map_methods.py compare --rounds 2 --block map_tolerance --methods \
		"independent;paths;independent, hold tolerance 3e-3;paths, hold tolerance 3e-3"

bit-identical: $(STAMP) base-tree  ## short runs of the shipped scenes: this tree bit-identical to BASE (default main)?
	PYTHONPATH=$(abspath $(BASE_TREE)) $(BIN)/python benchmarks/reference_positions.py $(OUT)/positions_base.npz
	PYTHONPATH=$(CURDIR) $(BIN)/python benchmarks/reference_positions.py $(OUT)/positions_here.npz
	$(BIN)/python benchmarks/reference_positions.py --compare $(OUT)/positions_base.npz $(OUT)/positions_here.npz

##@ Studies (studies/; each makes a figure or table of docs/, tests/test_studies_smoke.py runs it small)
.PHONY: phase fig3 lines figures docs-figures onset-study hat-curve stability-map damping-sweeps \
	ramp-rate \
	boundary-error crosscheck crosscheck-reference straight-start self-passage vibration-source \
	robustness study-shear study-damping study-friction study-neo-hookean study-contact \
	static-path hold-budget energy-audit twist-into-writhe twist-into-writhe-references
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

lines: $(STAMP)  ## Fig 3 as lines: the onset, the plectoneme-solenoid boundary, the triple point and where a rod turned back comes straight, with brackets
	@mkdir -p $(OUT)
	$(BIN)/rodphase boundaries fig3_paper -o $(OUT)/fig3_lines.h5 --csv $(OUT)/fig3_lines.csv --jobs $(JOBS) --quiet --hysteresis
	$(BIN)/rodphase plot $(OUT)/fig3_lines.h5 --kind phase -o $(OUT)/fig3_lines.png

figures: $(STAMP) fig3 lines  ## every figure of the paper (docs/explanation/validation.md), and Fig 3 as lines
	$(BIN)/python studies/figures.py --out $(OUT) --jobs $(JOBS)

# the figures docs/ shows: Fig 3's map (with its rows of docs/current.md) and the scene figures
DOC_FIGURES = fig2a fig2b fig4a fig4b fig4c figS9 figS3
docs-figures: current-fig3  ## redraw every figure of docs/img that validation shows (Fig 3 and the scene figures)
	$(BIN)/python studies/figures.py --out $(OUT) --jobs $(JOBS)
	for f in $(DOC_FIGURES); do cp $(OUT)/$$f.png docs/img/repro_$$f.png; \
		test ! -f $(OUT)/$${f}_shape.png || cp $(OUT)/$${f}_shape.png docs/img/repro_$${f}_shape.png; done

onset-study: $(STAMP)  ## the straight rod's onset line under stiffer shear and G = E/3 (docs/history/onset.md)
	$(BIN)/python studies/onset_study.py --write

hat-curve: $(STAMP)  ## hat curves: the scene at 25 F_C, then four forces (docs/history/scene-figures.md)
	@mkdir -p $(OUT)
	$(BIN)/rodphase run hat_curve -o $(OUT)/hat.h5
	$(BIN)/rodphase plot $(OUT)/hat.h5 --kind hat -o $(OUT)/hat.png
	$(BIN)/python studies/hat_curve.py $(OUT)/hat.h5
	$(BIN)/rodphase sweep configs/hat_forces.yaml -o $(OUT)/hat_forces.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/python studies/hat_curve.py $(OUT)/hat_forces.h5 --plot $(OUT)/hat_forces

stability-map: $(STAMP)  ## largest stable dt against the bound (docs/history/performance.md and its figure)
	$(BIN)/python studies/stability_map.py --json $(OUT)/perf/stability_map.json --write docs/history/performance.md

damping-sweeps: $(STAMP)  ## holds that settle: the damping variants on the figures, the demo, Fig 3 (docs/history/holds-and-laws.md)
	$(BIN)/python studies/damping_sweeps.py speed
	$(BIN)/python studies/damping_sweeps.py demo --out $(OUT)/damping
	$(BIN)/python studies/damping_sweeps.py figures --out $(OUT)/damping
	$(BIN)/python studies/damping_sweeps.py fig3 --out $(OUT)/damping

ramp-rate: $(STAMP)  ## Fig 3's twist ramp at several rates against a fine reference (docs/history/performance.md)
	$(BIN)/python studies/ramp_rate.py --rates 0.25,0.5,1,2 --jobs $(JOBS) --out $(OUT)/ramp --write docs/history/performance.md

# issue #29 item 4: Fig 3 under one change at a time, point by point against the map as it ships
VARIANTS_RUN = $(BIN)/python studies/map_variants.py --jobs $(JOBS) --out $(OUT)/variants --write docs/history/fig3-corner.md
study-shear: $(STAMP)  ## Fig 3 with shear stiffness x 10 and G = E/3 against the default (docs/history/fig3-corner.md)
	$(VARIANTS_RUN) shear_x10 g_e3 --figure docs/img/map_shear.png
study-damping: $(STAMP)  ## Fig 3 at half and twice the damping and without the quadratic drag
	$(VARIANTS_RUN) damping_half damping_twice no_drag --figure docs/img/map_damping.png
study-friction: $(STAMP)  ## Fig 3 with self-contact friction 0.2 and 0.5
	$(VARIANTS_RUN) friction_0.2 friction_0.5 --figure docs/img/map_friction.png
study-neo-hookean: $(STAMP)  ## Fig 3 with the conservative neo-Hookean law (from rest)
	$(VARIANTS_RUN) neo_hookean --figure docs/img/map_neo_hookean.png
study-contact: $(STAMP)  ## Fig 3 without the contact thinning force (PyElastica's contact)
	$(VARIANTS_RUN) no_thinning --figure docs/img/map_no_thinning.png

# issue #29 item 1: the five points of Fig 3 that fail, as `make fig3` runs them (seed 2020's Sobol points)
FIG3_FAILURES = --point 2.4115579335018995 1.093481214158237 --point 2.4905348515138033 1.1090010169893503 \
	--point 2.5258821224793793 1.079950714390725 --point 2.557734097540379 1.0524589744396509 \
	--point 2.5985506212338807 1.1349544170312584
energy-audit: $(STAMP)  ## Fig 3's five failures: the power the paper's law adds in their last second (reproduction.md)
	$(BIN)/python studies/energy_audit.py $(FIG3_FAILURES) --write docs/history/fig3-corner.md

# the random sweep is fig3's; the reference (24 x 24 by continuation) and the adaptive one are its own
boundary-error: fig3  ## phase-boundary error of random and adaptive sampling against a 24 x 24 reference
	$(BIN)/rodphase sweep configs/fig3_paper_reference.yaml -o $(OUT)/fig3_paper_reference.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/rodphase classify $(OUT)/fig3_paper_reference.h5 --csv $(OUT)/fig3_paper_reference.csv
	$(BIN)/rodphase sweep configs/fig3_paper_adaptive.yaml -o $(OUT)/fig3_paper_adaptive.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/rodphase classify $(OUT)/fig3_paper_adaptive.h5 --csv $(OUT)/fig3_paper_adaptive.csv
	$(BIN)/python studies/boundary_error.py $(OUT)/fig3_paper_reference.csv $(OUT)/fig3_paper.csv $(OUT)/fig3_paper_adaptive.csv

# CASE=solenoid or plectoneme; against the PyElastica run stored in tests/data
CASE ?= solenoid
crosscheck: $(STAMP)  ## PyElastica's own example CASE (default solenoid) in rodphase, compared (docs/img/crosscheck_CASE.png)
	@mkdir -p $(OUT)
	$(BIN)/python studies/crosscheck_pyelastica.py rodphase $(CASE) $(if $(filter plectoneme,$(CASE)),--end-bodies rod) -o $(OUT)/crosscheck_$(CASE).npz
	$(BIN)/python studies/crosscheck_pyelastica.py compare $(CASE) --rodphase $(OUT)/crosscheck_$(CASE).npz

crosscheck-reference: bench-extra  ## rerun example CASE in PyElastica 1.0 into tests/data (about an hour)
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference $(CASE)

twist-into-writhe: $(STAMP)  ## steps of twist into writhe, rodphase vs PyElastica one change at a time, and Fig 4a in both (docs/explanation/twist-into-writhe.md; ~30 min)
	$(BIN)/python studies/twist_into_writhe.py rows solenoid
	$(BIN)/python studies/twist_into_writhe.py rows plectoneme
	$(BIN)/python studies/twist_into_writhe.py table solenoid --write docs/explanation/twist-into-writhe.md
	$(BIN)/python studies/twist_into_writhe.py table plectoneme --write docs/explanation/twist-into-writhe.md
	$(BIN)/python studies/twist_into_writhe.py fig4a --write docs/explanation/twist-into-writhe.md
	$(BIN)/python studies/twist_into_writhe.py fig2 --write docs/explanation/twist-into-writhe.md

# dt 1e-4 s (4x the example's, half rodphase's bound): the twist prescribed at the example's
# as-run rate, the kick scaled to its force; the plain SolenoidsCase at that dt checks the step
AS_RUN = --dt 1e-4 --prescribe-twist 0.8279066 --final-time 85 --contact-from 50
twist-into-writhe-references: bench-extra  ## its PyElastica runs into tests/data: SolenoidsCase + thinning, 13-turn solenoid pulled, SolenoidsCase at dt 1e-4 (~1 h CPU)
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid --thinning 1.0 $(AS_RUN)
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid_pull --dt 1e-4 --contact-from 45 --sample 0.1
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid $(AS_RUN) --raw /tmp/crosscheck_raw_solenoid_dt1e-4.npz -o tests/data/crosscheck_solenoid_dt1e-4.npz
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid --thinning 1.0 --contact-split $(AS_RUN) --raw /tmp/crosscheck_raw_solenoid_rodphase_law.npz -o tests/data/crosscheck_solenoid_rodphase_law.npz
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid_pull --turns 10.19 --dt 1e-4 --contact-from 40 --sample 0.1 --raw /tmp/crosscheck_raw_solenoid_pull_10.npz -o tests/data/crosscheck_solenoid_pull_10.npz
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid --kick-shape uniform --dt 1e-4 --prescribe-twist 0.8279066 --final-time 72 --contact-from 50 --raw /tmp/crosscheck_raw_solenoid_uniform_kick.npz -o tests/data/crosscheck_solenoid_uniform_kick.npz
	NUMBA_NUM_THREADS=1 $(BIN)/python studies/crosscheck_pyelastica.py reference solenoid --thinning 1.0 --contact-split --final-time 85 --contact-from 50 --raw /tmp/crosscheck_raw_solenoid_rodphase_law_dt_example.npz -o tests/data/crosscheck_solenoid_rodphase_law_dt_example.npz

straight-start: $(STAMP)  ## Fig 3 with and without the quasi-static straight start (docs/history/performance.md)
	$(BIN)/python studies/straight_start.py --jobs $(JOBS) --out $(OUT)/straight --reference $(OUT)/perf/fig3_ref.h5 --write docs/history/performance.md

# one point of twist_under_load: PHI = Phi*a (rest), EXT = L/L0
PHI ?= 2.556
EXT ?= 1.265
self-passage: $(STAMP)  ## where a run's link went: each link jump of the point PHI, EXT located
	$(BIN)/python studies/self_passage.py --twist-density $(PHI) --extension $(EXT)

vibration-source: $(STAMP)  ## which part of the model sustains the vibration of a coil held in contact
	$(BIN)/python studies/vibration_source.py

robustness: $(STAMP)  ## the store under attack: kills, signals, a full disk, bad input (docs/explanation/robustness.md)
	$(BIN)/python studies/robustness.py --kills 60 --write docs/explanation/robustness.md

static-path: $(STAMP)  ## Fig 3 columns followed in twist by the static corrector, against the kernel (performance.md)
	$(BIN)/python studies/static_path.py --force-multiple 25 --start 0.9 --stop 1.25 --compare 1.0 1.1 1.25 --write docs/history/performance.md
	$(BIN)/python studies/static_path.py --force-multiple 90 --start 1.55 --stop 1.9 --compare 1.65 1.75 1.9 --write docs/history/performance.md

hold-budget: $(STAMP)  ## where fig3_paths' work goes: twist ramps against holds, how the holds end
	@mkdir -p $(OUT)
	$(BIN)/rodphase sweep configs/fig3_paths.yaml -o $(OUT)/fig3_paths.h5 --jobs $(JOBS) || [ $$? -eq 1 ]
	$(BIN)/python studies/hold_budget.py $(OUT)/fig3_paths.h5

include studies/figures.mk
