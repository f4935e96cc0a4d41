# The README's two commands. Both create .venv from this repo's own files.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# make test runs all but tests/e2e/ on both cores (pytest-xdist; each test file stays on one worker,
# so its module-scoped fixtures are built once), then tests/e2e/ alone: its processes run on the wall
# clock and flaked beside a CPU-bound test on 2 cores. JOBS=0 runs everything in one process
# (tests/README.md, "Parallel").
JOBS   ?= 2
PYTEST := $(PY) -m pytest -q -n $(JOBS) --dist loadfile --no-loadscope-reorder
E2E    := tests/e2e

.PHONY: demo test test-fast lint venv clean assets report bench bundle fuzz aarch64-check

$(STAMP): setup.cfg pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[robot,serial-imu,signed-models,train,export,sim,bench,dev]'
	touch $(STAMP)

venv: $(STAMP)

## make demo: the product on simulated devices with the shipped models (no hardware, no training)
demo: $(STAMP)
	$(PY) -m firmware_sim.demo --out demo_out

## make test: lint, then the whole suite (what .ci/run runs; under 15 minutes on 2 cores)
test: lint
	$(PYTEST) --ignore=$(E2E)
	$(PY) -m pytest -q $(E2E)

## make test-fast: lint, then every test that starts no process (the `slow` marker; tests/README.md)
test-fast: lint
	$(PYTEST) -m "not slow" --ignore=$(E2E)
	$(PY) -m pytest -q -m "not slow" $(E2E)

## make lint: ruff with the rules in pyproject.toml
lint: $(STAMP)
	$(PY) -m ruff check .

## rebuild the shipped models in edge_runtime/assets from a seed
assets: $(STAMP)
	$(PY) -m export assets --seed 0

## leave-one-subject-out report of every architecture (Tables 2.1-2.3)
report: $(STAMP)
	$(PY) -m models report --out reports/wearable --seed 0

bench: $(STAMP)
	$(PY) -m bench

## what goes onto a box: runtime wheel (no torch), assets, default config, checksums
bundle: $(STAMP)
	$(PY) -m export bundle --out dist/box --measure-install

## make fuzz: every parser and frame decoder with 100,000 mutated inputs each (fuzz/README.md).
## The hang limit is wall-clock: 60 s (as in tests/fuzz) so a loaded machine's scheduling is not a hang.
fuzz: $(STAMP)
	$(PY) -m fuzz --inputs 100000 --seed 0 --timeout-s 60 --json reports/fuzz/fuzz.json --md reports/fuzz/fuzz.md

## make aarch64-check: the aarch64 wearable bundle installed by its install.sh on an emulated arm64
## Debian 12 (qemu-user-static, proot, mmdebstrap, gcc-aarch64-linux-gnu), the same recording's alerts
## and CAN frames as the x86 bundle's (export/aarch64.py); writes reports/box/aarch64.{json,md}; not in make test
aarch64-check: $(STAMP)
	$(PY) -m export.aarch64 --report-dir reports/box

clean:
	rm -rf $(VENV) demo_out .pytest_cache
