# One-command set-up: `make demo` and `make test` create .venv when it is missing.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test test-slow test-all test-blas test-py test-pythons docs install bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

install: $(VENV)/.installed

# the documentation site (mkdocs-material, the API reference by mkdocstrings) into site/, strict:
# a warning (a broken link, a missing page, an unresolved reference) fails it
docs: install
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict

# one run into demo-out/, then the whole paper into its own folder demo-out/paper/ (a command's
# output folder holds only what that command writes); a second `make demo` replaces the run and
# reuses the paper's stored runs
demo: install
	$(BIN)/granel run paper --solid rigid --excite LSGM:3 --shock strong -o demo-out/paper-rigid-LSGM3-strong.nc
	$(BIN)/granel paper --out demo-out/paper
	@echo "make demo: open demo-out/paper/report.md"

test: install
	$(BIN)/python -m pytest -q -m "not slow"

test-slow: install
	$(BIN)/python -m pytest -q -m slow

test-all: install
	$(BIN)/python -m pytest -q

# the numerics-heavy tests under other OpenBLAS kernels than the machine's own, so that a bound
# tuned to one CPU's arithmetic fails here first (the kernel each run uses is printed)
BLAS_CORES ?= Sandybridge Prescott
BLAS_TESTS ?= tests/test_exact.py tests/test_solids.py tests/test_symmetry.py tests/test_mode_scaling.py \
	tests/test_propagation.py tests/test_conservation.py tests/test_core.py tests/test_narrowband_physics.py \
	tests/test_narrowband.py tests/test_validation.py tests/test_hertz_impact.py tests/test_nesterenko.py \
	tests/test_coupled.py
test-blas: install
	@echo "the machine's own kernel:"; $(BIN)/python tests/tools/blas_core.py || true
	@for core in $(BLAS_CORES); do \
	  echo "OPENBLAS_CORETYPE=$$core:"; OPENBLAS_CORETYPE=$$core $(BIN)/python tests/tools/blas_core.py || true; \
	  OPENBLAS_CORETYPE=$$core $(BIN)/python -m pytest -q -m "not slow" -p no:cacheprovider $(BLAS_TESTS) || exit 1; \
	done

# the quick subset on another interpreter present on this machine (make test-py PY=python3.13);
# MARK= (empty) runs the whole suite there
PY ?= python3.13
MARK ?= not slow
test-py:
	$(PY) -m venv .venv-$(notdir $(PY))
	.venv-$(notdir $(PY))/bin/python -m pip install --quiet --upgrade pip
	.venv-$(notdir $(PY))/bin/python -m pip install --quiet -e '.[test]'
	.venv-$(notdir $(PY))/bin/python -m pytest -q $(if $(MARK),-m "$(MARK)",)

# the whole suite on every Python 3.11-3.13 this machine has (a pyenv shim alone does not count)
test-pythons:
	@for v in 3.11 3.12 3.13; do \
	  py=""; \
	  for c in python$$v $${PYENV_ROOT:-$$HOME/.pyenv}/versions/$$v*/bin/python$$v; do \
	    if $$c -c "import sys" >/dev/null 2>&1; then py=$$c; break; fi; \
	  done; \
	  if [ -n "$$py" ]; then $(MAKE) test-py PY=$$py MARK= || exit 1; else echo "no Python $$v here"; fi; \
	done

bench: install
	$(BIN)/python benchmarks/bench_granular.py
	$(BIN)/python benchmarks/bench_scaling.py

clean:
	rm -rf $(VENV) .venv-python3.* .venv-user demo-out .pytest_cache
