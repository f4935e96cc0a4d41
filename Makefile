# The README's two commands. Both create .venv from this repo's own files.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test venv clean assets report bench bundle

$(STAMP): setup.cfg pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[train,sim,dev]'
	touch $(STAMP)

venv: $(STAMP)

## make demo: the product on simulated devices with the shipped models (no hardware, no training)
demo: $(STAMP)
	$(PY) -m firmware_sim.demo --out demo_out

## make test: the whole suite (under 15 minutes on 2 cores)
test: $(STAMP)
	$(PY) -m pytest -q

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

clean:
	rm -rf $(VENV) demo_out .pytest_cache
