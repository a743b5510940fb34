# tetc: every target sets up its own virtual environment in .venv on first use.
PY     ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
OUT    ?= out
# Two threads, as on the benchmark machines; override with NUMBA_NUM_THREADS=... make ...
export NUMBA_NUM_THREADS ?= 2

.PHONY: install test test-fast lint clean-cache demo bench clean distclean browser paraview gmsh-libs

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	$(BIN)/python -c 'import gmsh' 2>/dev/null || $(MAKE) gmsh-libs
	$(BIN)/python -m gatun_py.warmup
	touch $(STAMP)

test: $(STAMP) browser paraview
	$(BIN)/pytest -q

# The inner loop: the tests not marked slow (real data at full size, whole pipelines, installs).
test-fast: $(STAMP)
	$(BIN)/pytest -q -m "not slow"

# ruff with the config in pyproject.toml, and no fastmath in the codec (every float bit-exact).
lint: $(STAMP)
	$(BIN)/ruff check gatun_py cli tests bench
	@if grep -rnE "fastmath *=|[\"']fastmath[\"']" --include='*.py' gatun_py/codec; then \
	  echo "fastmath in gatun_py/codec: the codec's floats must stay bit-exact"; exit 1; fi

# numba's compiled kernels (next to the sources, in __pycache__): recompiled on the next run.
clean-cache:
	find gatun_py cli -path '*/__pycache__/*' \( -name '*.nbi' -o -name '*.nbc' \) -delete

# tests/test_viewer_browser.py drives headless Chromium (Debian's chromium and chromium-driver).
# Installed here when missing and we may (root with apt-get, as in CI); otherwise that test skips
# and says why. Quiet, and a failed install does not fail the build.
browser:
	@if ! command -v chromedriver >/dev/null 2>&1 || ! command -v chromium >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing chromium and chromium-driver for the browser test..."; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver \
	      >/dev/null 2>&1) || echo "note: could not install chromium; the browser test will skip"; \
	  else \
	    echo "note: chromium/chromedriver not found (install Debian's chromium chromium-driver); the browser test will skip"; \
	  fi; \
	fi

# tests/test_paraview_plugin.py loads the reader plugin in Debian's ParaView (pvbatch under xvfb-run).
# Installed here when missing and we may (root with apt-get, as in CI); otherwise that test skips and
# says why. Quiet, and a failed install does not fail the build.
paraview:
	@if ! command -v pvbatch >/dev/null 2>&1 || ! command -v xvfb-run >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing paraview and xvfb for the ParaView plugin test..."; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq paraview xvfb \
	      >/dev/null 2>&1) || echo "note: could not install paraview; the ParaView plugin test will skip"; \
	  else \
	    echo "note: pvbatch/xvfb-run not found (install Debian's paraview xvfb); the ParaView plugin test will skip"; \
	  fi; \
	fi

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
	$(BIN)/python -c 'import gmsh' 2>/dev/null || $(MAKE) gmsh-libs
	$(BIN)/python bench/run.py

# gmsh's wheel (the unstructured test meshes, bench/gmsh_meshes.py) links X11/OpenGL libraries that a
# bare Debian machine lacks; installed only when `import gmsh` fails, and only where apt-get runs.
gmsh-libs:
	@if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
		apt-get update -qq && apt-get install -y -qq libglu1-mesa libgl1 libxcursor1 libxft2 libxinerama1 \
			libxrender1 libfontconfig1 libgomp1 >/dev/null; \
	else echo "gmsh needs libGLU, libXcursor, libXft, libXinerama: install them (tests using gmsh meshes skip)"; fi

clean:
	rm -rf $(OUT) build dist *.egg-info .pytest_cache .hypothesis
	find . -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
