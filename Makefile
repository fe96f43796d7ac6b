# make demo: install everything, generate a sample dataset, convert it, train a small
# 2D->3D lifting model on it for a few epochs and print its results table.
# make test: install everything, build, run the C++ (ctest) and Python (pytest) tests.
# make test-asan / test-tsan / fuzz FUZZ_SECONDS=N: sanitizer builds and the fuzzers
# (docs/security.md, "Fuzzing and sanitizers"), each in its own build directory.
# make wheel: a self-contained manylinux wheel in dist/ (docs/install.md); make wheel-check:
# that wheel installed and run on an emulated machine without compilers (CI runs it).
# make wheels: one such wheel per supported CPython, 3.10 to 3.13; make wheels-check: each
# built and run in a clean venv of its own Python, with the torch extra (docs/install.md).
SHELL := /bin/bash
PY = $$(cat build/.python)
WERROR ?= OFF
# C++ unit tests (doctest): off for a plain install, on for `make test`.
TESTS ?= OFF

.PHONY: all deps install test test-cpp test-python demo bench clean \
	fuzz fuzz-one fuzz-build test-asan test-asan-cpp test-tsan wheel wheel-check \
	wheels wheels-check
all: install

deps:
	@bash tools/install-deps.sh

install: deps
	@echo "building and installing bsp_fast (C++ core, incremental in build/wheel)"
	@$(PY) -m pip install -q --no-build-isolation --no-deps \
	    -Ccmake.define.BSP_WERROR=$(WERROR) -Ccmake.define.BSP_TESTS=$(TESTS) .

test: deps
	@$(MAKE) --no-print-directory install TESTS=ON
	@$(MAKE) --no-print-directory test-cpp test-python

# --no-tests=error: a build without the C++ tests (TESTS=OFF) fails here instead of passing.
test-cpp:
	ctest --test-dir build/wheel --output-on-failure --no-tests=error -j2

# Two pytest workers (pytest-xdist), one per core of the 2-core machines; a file's tests
# stay on one worker (--dist loadfile), so its module fixtures are made once.
PYTEST_WORKERS ?= 2
test-python:
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile tests/python

# ---------------------------------------------------------------- wheels
# The binary wheel, built in build/wheel like `install` (after it nothing recompiles), then
# repaired by auditwheel: every shared library the core needs is copied into the wheel.
wheel: deps
	@bash tools/build_wheel.sh $(PY)

wheel-check: deps
	@bash tools/wheel_check.sh "" $(PY)

# One wheel per CPython (3.10-3.13; VERSIONS="3.12" for fewer), each with its own build
# environment and build directory under build/wheels/ (never build/wheel: `make install`'s
# stays as it is); with ccache the core's objects are compiled once for all four.
VERSIONS ?= 3.10 3.11 3.12 3.13
wheels: deps
	@bash tools/build_wheels.sh $(VERSIONS)

# The matrix: each wheel built (incrementally) and checked in a fresh venv of its Python
# on the emulated bare machine, with the torch and preview extras and a one-epoch bsp-train;
# its table in build/wheels/matrix.md.
wheels-check: deps
	@bash tools/wheel_matrix.sh $(VERSIONS)

# ---------------------------------------------------------------- sanitizers and fuzzing
# Builds in build/asan, build/tsan and build/fuzz with their own flags; build/wheel (the
# installed module) is never touched. Configure once, then incremental like `install`.
SAN_CMAKE = cmake -S . --no-warn-unused-cli -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBSP_WERROR=$(WERROR) \
	-DPython_EXECUTABLE=$$(command -v $(PY))
# Python tests that drive the C++ core (readers, converter, hostile inputs), run against
# the ASan build of _core: python itself is not instrumented, so libasan is preloaded.
ASAN_PYTESTS ?= tests/python/test_hostile.py tests/python/test_csv.py \
	tests/python/test_media_apng.py tests/python/test_media_video.py \
	tests/python/test_convert_media.py
UBSAN_ENV = UBSAN_OPTIONS=print_stacktrace=1
# (python's own allocations live until exit: no leak check there; libstdc++ is preloaded
# too, or ASan finds no real __cxa_throw to forward the core's first exception to)
PY_ASAN_ENV = $(UBSAN_ENV) ASAN_OPTIONS=detect_leaks=0 \
	LD_PRELOAD="$$(gcc -print-file-name=libasan.so) $$(gcc -print-file-name=libstdc++.so)"
# A small dataset with media for the converter-threads driver (tests/sanitize).
san_dataset = $(PY) -m bsp_fast synth $(1) --clips 6 --frames 40 --size 96x64 --seed 7 \
	--workers 1 --quiet --force

test-asan: deps
	$(SAN_CMAKE) -B build/asan -DBSP_SANITIZE=address,undefined -DBSP_TESTS=ON -DBSP_PYTHON=ON
	cmake --build build/asan -j2
	$(UBSAN_ENV) ctest --test-dir build/asan --output-on-failure --no-tests=error -j2
	@rm -rf build/asan/convert-out
	$(call san_dataset,build/asan/convert.dataset)
	$(UBSAN_ENV) build/asan/bsp_convert_threads build/asan/convert.dataset build/asan/convert-out 3
	$(PY_ASAN_ENV) PYTHONPATH=build/asan/py:python $(PY) -m pytest -q -p no:cacheprovider $(ASAN_PYTESTS)

# The ASan ctest only (CI: the Python half runs in `make test` without a sanitizer).
test-asan-cpp: deps
	$(SAN_CMAKE) -B build/asan -DBSP_SANITIZE=address,undefined -DBSP_TESTS=ON -DBSP_PYTHON=OFF
	cmake --build build/asan -j2
	$(UBSAN_ENV) ctest --test-dir build/asan --output-on-failure --no-tests=error -j2

# ThreadSanitizer: the C++ tests (the threaded ones: parallel_for, the CSV reader's row
# blocks, the APNG decode-ahead and video converter threads) and the converter's workers
# and cancellation on a real dataset.
TSAN_ENV = TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1
test-tsan: deps
	$(SAN_CMAKE) -B build/tsan -DBSP_SANITIZE=thread -DBSP_TESTS=ON -DBSP_PYTHON=OFF
	cmake --build build/tsan -j2
	$(TSAN_ENV) ctest --test-dir build/tsan --output-on-failure --no-tests=error -j2
	@rm -rf build/tsan/convert-out
	$(call san_dataset,build/tsan/convert.dataset)
	$(TSAN_ENV) build/tsan/bsp_convert_threads build/tsan/convert.dataset build/tsan/convert-out 3

# libFuzzer harnesses (tests/fuzz): clang, -fsanitize=fuzzer,address,undefined. Each runs
# FUZZ_SECONDS from its committed seeds (tests/fuzz/corpus/<name>) plus what earlier runs
# found (build/fuzz/corpus/<name>); a crash stops make and leaves its input in
# build/fuzz/crashes/.
FUZZ_SECONDS ?= 60
FUZZ_HARNESSES = csv apng video
FUZZ_FLAGS ?= -rss_limit_mb=2048 -timeout=25 -print_final_stats=1
fuzz-build: deps
	@bash tools/install-fuzz-deps.sh
	$(SAN_CMAKE) -B build/fuzz -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
	    -DBSP_SANITIZE=address,undefined -DBSP_FUZZ=ON -DBSP_TESTS=OFF -DBSP_PYTHON=OFF
	cmake --build build/fuzz -j2 --target $(addprefix fuzz_,$(FUZZ_HARNESSES))

fuzz: fuzz-build
	@mkdir -p build/fuzz/crashes
	@printf '%s\n' $(FUZZ_HARNESSES) | xargs -P $(FUZZ_JOBS) -I{} $(MAKE) -s fuzz-one H={}

# One harness; `make fuzz` runs FUZZ_JOBS of them at once (default 2: one per core of the
# 2-core machines, so each still gets FUZZ_SECONDS of a core and the wall time halves).
FUZZ_JOBS ?= 2
fuzz-one:
	@mkdir -p build/fuzz/corpus/$(H)
	@echo "fuzz_$(H): $(FUZZ_SECONDS) s (log: build/fuzz/$(H).log)"
	@ASAN_OPTIONS=detect_leaks=1 $(UBSAN_ENV) \
	  build/fuzz/fuzz_$(H) build/fuzz/corpus/$(H) tests/fuzz/corpus/$(H) \
	    -max_total_time=$(FUZZ_SECONDS) $(FUZZ_FLAGS) \
	    -artifact_prefix=build/fuzz/crashes/$(H)- > build/fuzz/$(H).log 2>&1; rc=$$?; \
	  grep -E '^#[0-9]+[[:space:]]+(INITED|DONE)|^stat::(number_of_executed_units|average_exec_per_sec|peak_rss)' \
	    build/fuzz/$(H).log | sed 's/^/fuzz_$(H): /'; \
	  if [ $$rc -ne 0 ]; then tail -n 60 build/fuzz/$(H).log; \
	    echo "fuzz_$(H) failed (exit $$rc): input in build/fuzz/crashes/"; exit 1; fi

# Each step is echoed as a user types it (the console script and its options), and run
# through the Python `make install` installed into, whose scripts may not be on PATH.
bsp = @echo '$$ bsp-$(1) $(2)' && $(PY) -m bsp_fast $(1) $(2)

demo: install
	$(call bsp,synth,demo-out/dataset --preset sample --force)
	$(call bsp,convert,demo-out/dataset demo-out/clips.h5 --verify --strict --force)
	@echo '$$ python tools/h5_summary.py demo-out/clips.h5' && $(PY) tools/h5_summary.py demo-out/clips.h5
	$(call bsp,train,lifting lstm --data demo-out/dataset --clip-length 16 --clip-offset 4 --epochs 8 --batch-size 8 --lr 1e-3 --seed 1 --threads 1 --out demo-out/runs/lifting-lstm --force --quiet)
	$(call bsp,eval,--table demo-out/runs/lifting-lstm)

# The speed comparisons behind the README's tables (several minutes; not part of the tests).
bench: install
	$(PY) benchmarks/bench_kinematics.py
	$(PY) benchmarks/bench_csv.py
	$(PY) benchmarks/bench_convert.py
	$(PY) benchmarks/bench_media.py
	$(PY) benchmarks/bench_convert_media.py
	$(PY) benchmarks/bench_loader.py
	$(PY) benchmarks/bench_synth.py
	$(PY) benchmarks/bench_synth_poses.py --convert
	$(PY) benchmarks/bench_metrics.py

clean:
	rm -rf build dist *.egg-info demo-out
