#!/usr/bin/env bash
# The wheel matrix (docs/install.md, "One wheel per Python"): for each supported CPython its
# wheel is built (tools/build_wheels.sh, incremental) and checked by tools/wheel_check.sh
# in a fresh virtual environment of that interpreter, without system site-packages, on the
# emulated bare machine: auditwheel show, `pip install --only-binary :all:`, import,
# bsp-synth + bsp-convert --verify of the sample, h5py beside the core, and the extras of
# WHEEL_CHECK_EXTRAS with, where torch is among them, a one-epoch bsp-train.
#
#   bash tools/wheel_matrix.sh [--no-build] [VERSION...]   (default: 3.10 3.11 3.12 3.13)
#
# --no-build checks the wheels already in dist/ (make wheels) as they are.
# WHEEL_CHECK_EXTRAS: default here `torch,preview` (PyTorch publishes wheels for all four;
# pip takes torch from PyPI, on Linux the CUDA build: about 5 GB per venv, removed after).
#
# Every version runs even when an earlier one fails. Logs and measurements are kept in
# build/wheels/cp3X/ (check.log, summary.txt); the table of the results is printed last and
# written to build/wheels/matrix.md. Exit 1 when any version failed.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=1
if [ "${1:-}" = "--no-build" ]; then
  BUILD=
  shift
fi
VERSIONS=("$@")
if [ ${#VERSIONS[@]} -eq 0 ]; then
  VERSIONS=(3.10 3.11 3.12 3.13)
fi
export WHEEL_CHECK_EXTRAS=${WHEEL_CHECK_EXTRAS-torch,preview}

# check_one 3.12: builds (unless --no-build) and checks the cp312 wheel; returns non-zero
# on the first step that fails, its output in build/wheels/cp312/check.log.
check_one() {
  local version=$1
  local dir=build/wheels/cp${version/./}
  local wheel show=
  mkdir -p "$dir"
  rm -f "$dir/summary.txt"
  if [ -n "$BUILD" ]; then
    bash tools/build_wheels.sh "$version" 2>&1 | tee "$dir/build.log" || return 1
    show=$dir/show.txt  # build_wheels.sh's `auditwheel show` of the wheel it just made
  fi
  wheel=$(ls dist/bsp_fast-*-cp${version/./}-cp${version/./}-manylinux*.whl 2>/dev/null) ||
    { echo "wheel_matrix: $version: no wheel in dist/ (make wheels)" >&2; return 1; }
  WHEEL_CHECK_SHOW=$show WHEEL_CHECK_SUMMARY=$dir/summary.txt \
    bash tools/wheel_check.sh "$wheel" "$dir/env/bin/python" 2>&1 | tee "$dir/check.log"
}

failed=()
for version in "${VERSIONS[@]}"; do
  echo "wheel_matrix: ---------------- CPython $version"
  if ! check_one "$version"; then
    failed+=("$version")
    echo "wheel_matrix: $version FAILED (build/wheels/cp${version/./}/*.log)" >&2
  fi
done

# The table, from each version's summary.txt (KEY=VALUE lines written by wheel_check.sh)
python3 - "$WHEEL_CHECK_EXTRAS" "${VERSIONS[@]}" <<'PYEOF' | tee build/wheels/matrix.md
import os, sys

extras, versions = sys.argv[1], sys.argv[2:]
print(f"| Python | wheel (MB) | libraries | venv + install (s) | installed (MiB) "
      f"| synth / convert (s) | [{extras}] install (s) | with extras (MiB) | torch "
      f"| 1-epoch bsp-train (s) | result |")
print("|---" * 11 + "|")
for version in versions:
    path = f"build/wheels/cp{version.replace('.', '')}/summary.txt"
    s = dict(line.rstrip("\n").split("=", 1) for line in open(path)) \
        if os.path.exists(path) else {}
    ok = "check_s" in s  # written only when every step passed
    get = lambda key: s.get(key, "–")
    print(f"| {get('python') if 'python' in s else version} | {get('wheel_mb')} "
          f"| {get('libraries')} | {get('venv_s')} + {get('install_s')} | {get('venv_mib')} "
          f"| {get('synth_s')} / {get('convert_s')} | {get('extras_s')} "
          f"| {get('extras_venv_mib')} | {get('torch')} | {get('train_s')} "
          f"| {'OK in ' + s['check_s'] + ' s' if ok else 'FAILED'} |")
PYEOF
if [ ${#failed[@]} -gt 0 ]; then
  echo "wheel_matrix: failed: ${failed[*]}" >&2
  exit 1
fi
echo "wheel_matrix: all passed: ${VERSIONS[*]}"
