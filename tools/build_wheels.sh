#!/usr/bin/env bash
# One repaired manylinux wheel per supported CPython (docs/install.md, "One wheel per
# Python"): `make wheels`.
#
#   bash tools/build_wheels.sh [VERSION...]      (default: 3.10 3.11 3.12 3.13)
#
# For each version: its interpreter (python3.X that runs, else pyenv's newest 3.X.*), a
# build environment of its own with the pinned build requirements (build/wheels/cp3X/env),
# `pip wheel --no-build-isolation` with the C++ core compiled in build/wheels/cp3X/cmake,
# then the repair of tools/build_wheel.sh (the same vendored libraries for every Python)
# and `auditwheel show`, which must find the wheel consistent with a manylinux tag.
# Leaves dist/bsp_fast-<version>-cp3X-cp3X-manylinux_2_<N>_x86_64.whl and prints one line
# per wheel, "VERSION PATH", last. Incremental: a second run compiles only what changed.
#
# Each Python has its own build directory, and none is build/wheel (`make install`'s): a
# build directory's CMake cache holds one interpreter's paths, so each stays incremental.
#
# Where ccache is on PATH it is the compilers' launcher: the core's objects (38 of the 46)
# do not depend on the Python, so the second and later interpreters compile only the 8
# files of the bindings.
#
# Environment: WHEELS_BUILD_LOCK=FILE takes `flock FILE` around each compile (checkouts
# sharing a machine then never compile at once); WERROR=ON builds with warnings as errors
# (as `make test WERROR=ON`; CI); CMAKE_BUILD_PARALLEL_LEVEL (default 2).
set -euo pipefail
cd "$(dirname "$0")/.."
VERSIONS=("$@")
if [ ${#VERSIONS[@]} -eq 0 ]; then
  VERSIONS=(3.10 3.11 3.12 3.13)
fi
# Pinned, so that every wheel is built by the same backend whatever PyPI holds that day
# (the versions `make deps` installed on the build machines when this was written).
BUILD_REQUIREMENTS=("scikit-build-core==1.1.2" "pybind11==3.1.0")
# --config-settings, not -C: the pip of a fresh 3.10 venv (23.0) has no -C
SETTINGS=(--config-settings=cmake.define.BSP_WERROR="${WERROR:-OFF}")
if command -v ccache >/dev/null; then
  SETTINGS+=(--config-settings=cmake.define.CMAKE_CXX_COMPILER_LAUNCHER=ccache
             --config-settings=cmake.define.CMAKE_C_COMPILER_LAUNCHER=ccache)
fi

# find_python 3.12: the path of a CPython 3.12, or exit 1 saying where it looked. pyenv's
# shims answer `command -v python3.12` even when 3.12 is not the selected version and then
# fail when run, so a candidate counts only once it runs and says it is 3.12.
find_python() {
  local want=$1 candidate
  local pyenv_root=${PYENV_ROOT:-$HOME/.pyenv}
  local says='import sys; print("%d.%d" % sys.version_info[:2])'
  local candidates=("$(command -v "python$want" || true)")
  candidates+=($(ls -d "$pyenv_root"/versions/"$want".*/bin/"python$want" 2>/dev/null |
                 sort -rV))
  for candidate in "${candidates[@]}"; do
    if [ -n "$candidate" ] && [ "$("$candidate" -c "$says" 2>/dev/null)" = "$want" ]; then
      echo "$candidate"
      return
    fi
  done
  echo "build_wheels: no CPython $want (no python$want on PATH, none in" \
       "$pyenv_root/versions)" >&2
  return 1
}

# build_one 3.12: builds and repairs the cp312 wheel; adds "3.12 PATH" to BUILT.
BUILT=()
build_one() {
  local version=$1
  local dir=build/wheels/cp${version/./}
  local python env_py start wheel
  python=$(find_python "$version")
  env_py=$dir/env/bin/python
  if ! "$env_py" -c '' 2>/dev/null; then
    echo "build_wheels: $version: build environment $dir/env ($python)"
    rm -rf "$dir/env"
    "$python" -m venv "$dir/env"
  fi
  # every time: nothing is fetched while the pins are installed, and a changed pin applies
  "$env_py" -m pip install -q "${BUILD_REQUIREMENTS[@]}"
  rm -rf "$dir/raw"
  echo "build_wheels: $version: pip wheel (C++ core in $dir/cmake)"
  start=$SECONDS
  # ${WHEELS_BUILD_LOCK:+...}: the flock prefix only when a lock file is given
  CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2} \
    ${WHEELS_BUILD_LOCK:+flock "$WHEELS_BUILD_LOCK"} \
    "$env_py" -m pip wheel -q --no-deps --no-build-isolation \
      --config-settings=build-dir="$dir/cmake" "${SETTINGS[@]}" -w "$dir/raw" .
  echo "build_wheels: $version: built in $((SECONDS - start)) s"
  bash tools/build_wheel.sh --repair "$dir"/raw/bsp_fast-*.whl "$env_py" | tee "$dir/repair.log"
  wheel=$(tail -n 1 "$dir/repair.log")
  # auditwheel's own verdict on the repaired wheel (tools/wheel_check.sh checks more)
  build/wheel-tools/bin/auditwheel show "$wheel" > "$dir/show.txt" 2>&1
  if ! tr -s ' \n' ' ' < "$dir/show.txt" |
       grep -q 'is consistent with the following platform tag: "manylinux_'; then
    cat "$dir/show.txt" >&2
    echo "build_wheels: $version: auditwheel show: not a manylinux wheel" >&2
    return 1
  fi
  echo "build_wheels: $version: auditwheel show: $(tr -s ' \n' ' ' < "$dir/show.txt" |
        grep -o 'platform tag: "[^"]*"' | head -n 1)"
  BUILT+=("$version $wheel")
}

for version in "${VERSIONS[@]}"; do
  build_one "$version"
done
printf '%s\n' "${BUILT[@]}"
