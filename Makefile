# The two quickstart commands are `make demo` and `make test`; everything else is theirs.
VENV ?= .venv
PY := $(VENV)/bin/python
DEBS := socat mbpoll chromium tmux

.PHONY: setup system-deps demo test check bench paper soak lab-ci examples docs

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

setup: $(VENV)/.installed system-deps $(VENV)/.kernels

# numba compiles the kernels on first use (~45 s); do it here, not in the first run
$(VENV)/.kernels: $(VENV)/.installed $(wildcard sim/*.py sim/*/*.py)
	$(VENV)/bin/bench warmup
	touch $@

# Test peers from Debian (pseudo-terminal pairs, an independent Modbus client, a real
# browser for the HTML pages, a terminal multiplexer for the 80-column progress line).
system-deps:
	@missing=""; for p in $(DEBS); do command -v $$p >/dev/null || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq $$missing >/dev/null; \
	fi

demo: setup
	$(VENV)/bin/bench demo --out out/demo

paper: setup
	$(VENV)/bin/bench paper --out out/paper

# Two workers (the machines have 2 cores); the scheduler of tests/conftest.py keeps a module's
# tests, and so its module-scoped fixtures (a run made once and read by many tests), on one
# worker and starts the longest modules first (decision 0046).  One BLAS thread each: two
# workers with OpenBLAS's two threads each oversubscribe the cores and its threads spin (the
# analysis test's fixture took 59 s of CPU with them, 25.5 s with one; decision 0062).
# The statistical campaigns and long process tests (marker `campaign`) run in `make bench`; a
# small seeded sample of each stays here (decision 0083).
test: setup
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist loadscope --durations=15 -m "not campaign"

# A lab's CI from a fresh install (CI runs it after the tests): the package's wheel into a new
# virtual environment, then examples/lab-ci's own tests, which use only `import bench` and the
# pytest plugin, run from a copy outside the source tree (decision record 0055).
LAB := out/lab-ci
lab-ci: setup
	rm -rf $(LAB) && mkdir -p $(LAB)
	$(PY) -m pip wheel -q --no-deps -w $(LAB)/dist .
	python3 -m venv $(LAB)/venv
	$(LAB)/venv/bin/python -m pip install -q $(LAB)/dist/guideway_bench-*.whl 'pytest>=8,<10'
	cp -r examples/lab-ci $(LAB)/project
	cd $(LAB)/project && ../venv/bin/python -c "import bench, sys; assert '/venv/' in bench.__file__, bench.__file__"
	cd $(LAB)/project && ../venv/bin/python -m pytest -q -p no:cacheprovider

# Both examples as their users meet them (CI runs this after the tests): the lab's CI above,
# then examples/tutorial.ipynb executed top to bottom in a fresh kernel of that environment.
examples: lab-ci
	$(LAB)/venv/bin/python -m pip install -q 'nbclient>=0.10,<1' 'nbformat>=5.10,<6' 'ipykernel>=6.29,<8'
	mkdir -p $(LAB)/notebook
	$(LAB)/venv/bin/python examples/run_notebook.py examples/tutorial.ipynb $(LAB)/notebook

# The documentation site into out/site (CI runs it): the key reference generated from the
# parser (docs/gen_keys.py), then mkdocs with warnings as errors (strict: true in mkdocs.yml).
docs: setup
	$(PY) -m pip install -q -e '.[test,docs]'
	$(PY) docs/gen_keys.py
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# Static checks (CI runs them before the tests): lint and import order, the layer
# contract bench -> procedures -> drivers -> sim, types of sim/, drivers/, procedures/.
check: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mypy

# First the tests of marker `campaign` (the cases `make test` keeps a seeded sample of, 0083).
# The last bench_analysis line: 90-step independent cases whose records keep the carriage's
# free vibration (25 settle cycles): the time bench analyze spends, no line where none was put (0045).
# bench_signals: 20 runs, a random ending signal in stepped sine, response control, phase
# resonance, a dwell and the report (0040, 0051; about 5 min).
# bench_import_coverage: imported FRFs of the independent simulator, 5 levels x 40 seeds, each
# interval against the simulator's truth (0085; about 25 min of one core).
bench: setup
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist loadscope -m campaign
	$(PY) benchmarks/bench_sim.py
	$(PY) benchmarks/bench_drivers.py
	$(PY) benchmarks/bench_procedure.py
	$(PY) benchmarks/bench_studies.py
	$(PY) benchmarks/bench_analysis.py
	$(PY) benchmarks/bench_analysis.py --source independent --cases 60 --levels 3 --freqs 10
	$(PY) benchmarks/bench_analysis.py --source independent --cases 12 --settle 25
	$(PY) benchmarks/bench_hum.py
	$(PY) benchmarks/bench_artefacts.py
	$(PY) benchmarks/bench_signals.py
	$(PY) benchmarks/bench_identification.py
	$(PY) benchmarks/bench_mc_coverage.py
	$(PY) benchmarks/bench_backbone.py
	$(PY) benchmarks/bench_twin.py
	$(PY) benchmarks/bench_modes.py --seeds 6
	$(PY) benchmarks/bench_modes_coverage.py --seeds 3
	$(PY) benchmarks/bench_import_coverage.py --seeds 40
	$(PY) benchmarks/bench_friction_models.py
	$(PY) benchmarks/bench_describing_fit.py
	$(PY) benchmarks/bench_model_choice.py

# Soak test (by hand, not in `make test`): 2000 steps, ~3 h of rig time, twins hammered by
# other clients; prints memory, open files, latencies. SOAK_PROFILE=short for a quick one.
SOAK_PROFILE ?= full
soak: setup
	$(PY) benchmarks/soak.py --profile $(SOAK_PROFILE) --out out/soak
