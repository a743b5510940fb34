# tetc: every target sets up its own virtual environment in .venv on first use.
PY     ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
OUT    ?= out
# Two threads, as on the benchmark machines; override with NUMBA_NUM_THREADS=... make ...
export NUMBA_NUM_THREADS ?= 2

.PHONY: install test demo bench clean distclean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	$(BIN)/python -m gatun_py.warmup
	touch $(STAMP)

test: $(STAMP)
	$(BIN)/pytest -q

# The main job on a bundled sample: compress Blunt-fin losslessly with its pre-simplified levels,
# then decode, simplify and render it in one streaming pass (full and 90 % simplified).
demo: $(STAMP)
	mkdir -p $(OUT)
	$(BIN)/tetc info sample_meshes/bluntfin/bluntfinxyz.bin
	$(BIN)/tetc compress sample_meshes/bluntfin/bluntfinxyz.bin -o $(OUT)/bluntfin.tetc --force
	$(BIN)/tetc info $(OUT)/bluntfin.tetc
	$(BIN)/tetc render $(OUT)/bluntfin.tetc -o $(OUT)/bluntfin.png --tf bluntfin --azimuth 30 --elevation 20 --size 512 --force --stats
	$(BIN)/tetc render $(OUT)/bluntfin.tetc -o $(OUT)/bluntfin_r90.png --tf bluntfin --azimuth 30 --elevation 20 --size 512 --ratio 0.9 --force --stats
	$(BIN)/tetc compare $(OUT)/bluntfin.png $(OUT)/bluntfin_r90.png
	@echo "images: $(OUT)/bluntfin.png $(OUT)/bluntfin_r90.png"

# Benchmarks against the peers (xz, fpzip, VTK): writes bench/REPORT.md and bench/figures/.
bench: $(STAMP)
	$(BIN)/pip install -q -e '.[test,bench,vtk]'
	$(BIN)/python bench/run.py

clean:
	rm -rf $(OUT) build dist *.egg-info .pytest_cache .hypothesis
	find . -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
