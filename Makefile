# make demo: install everything, generate a sample dataset, convert it, train a small
# 2D->3D lifting model on it for a few epochs and print its results table.
# make test: install everything, build, run the C++ (ctest) and Python (pytest) tests.
SHELL := /bin/bash
PY = $$(cat build/.python)
WERROR ?= OFF
# C++ unit tests (doctest): off for a plain install, on for `make test`.
TESTS ?= OFF

.PHONY: all deps install test test-cpp test-python demo bench clean
all: install

deps:
	@bash tools/install-deps.sh

install: deps
	@# the 'distributed' extra (bsp-convert/bsp-synth --scheduler dask), pinned exactly
	@$(PY) -m pip install -q "dask[distributed]==2026.8.0" "distributed==2026.8.0"
	@echo "building and installing bsp_fast (C++ core, incremental in build/wheel)"
	@$(PY) -m pip install -q --no-build-isolation --no-deps \
	    -Ccmake.define.BSP_WERROR=$(WERROR) -Ccmake.define.BSP_TESTS=$(TESTS) .

test: deps
	@$(MAKE) --no-print-directory install TESTS=ON
	@$(MAKE) --no-print-directory test-cpp test-python

# --no-tests=error: a build without the C++ tests (TESTS=OFF) fails here instead of passing.
test-cpp:
	ctest --test-dir build/wheel --output-on-failure --no-tests=error -j2

test-python:
	$(PY) -m pytest -q tests/python

demo: install
	$(PY) -m bsp_fast synth demo-out/dataset --preset sample --force
	$(PY) -m bsp_fast convert demo-out/dataset demo-out/clips.h5 --verify --strict --force
	$(PY) tools/h5_summary.py demo-out/clips.h5
	$(PY) -m bsp_fast train lifting lstm --data demo-out/dataset --clip-length 16 \
	    --clip-offset 4 --epochs 8 --batch-size 8 --lr 1e-3 --seed 1 --threads 1 \
	    --out demo-out/runs/lifting-lstm --force --quiet
	$(PY) -m bsp_fast eval --table demo-out/runs/lifting-lstm

# The speed comparisons behind the README's tables (several minutes; not part of the tests).
bench: install
	$(PY) benchmarks/bench_kinematics.py
	$(PY) benchmarks/bench_csv.py
	$(PY) benchmarks/bench_convert.py
	$(PY) benchmarks/bench_media.py
	$(PY) benchmarks/bench_convert_media.py
	$(PY) benchmarks/bench_loader.py
	$(PY) benchmarks/bench_synth.py
	$(PY) benchmarks/bench_metrics.py

clean:
	rm -rf build dist *.egg-info demo-out
