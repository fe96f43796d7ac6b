#!/usr/bin/env bash
# Installs everything bsp_fast needs to build, test and run, on Debian 12 as root.
# Idempotent: packages already present are not fetched again. Prints nothing but
# progress; exits non-zero when something cannot be installed.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(
  build-essential pkg-config cmake git
  libeigen3-dev libopencv-dev libassimp-dev libhdf5-dev libfast-float-dev libdeflate-dev
  zlib1g-dev doctest-dev
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev ffmpeg
)
PIP_PACKAGES=(
  "numpy>=1.22" "h5py>=3.8" "pyyaml>=6" "tqdm>=4.60" "pandas>=2" "pytest>=7" "pytest-xdist>=3.5" "av>=12"
  "pillow>=10" "pyarrow>=14" "scikit-build-core>=0.10" "pybind11>=2.12"
  "opencv-python-headless>=4.8" "matplotlib>=3.5" "scipy>=1.9" "pycocotools>=2.0.6"
  # Pinned exactly: this version's CPU build is on the machine; a looser pin pulls a
  # multi-GB CUDA build.
  "torch==2.13.0" "lightning>=2.2" "jsonargparse>=4.39,<5"
  # the 'distributed' extra (bsp-convert/bsp-synth --scheduler dask; its tests), pinned
  "dask[distributed]==2026.8.0" "distributed==2026.8.0"
)

bash tools/apt-ensure.sh install-deps "${APT_PACKAGES[@]}"

# The Python to use: the first python3 with a working, writable pip; otherwise (a fresh
# Debian whose system Python is externally managed) a virtual environment in .venv.
pick_python() {
  if [ -x .venv/bin/python ]; then echo .venv/bin/python; return; fi
  if python3 -m pip --version >/dev/null 2>&1 &&
     python3 -c 'import sys,sysconfig,os; sys.exit(os.path.exists(os.path.join(sysconfig.get_path("stdlib"),"EXTERNALLY-MANAGED")))'; then
    echo python3; return
  fi
  echo "install-deps: creating .venv (system Python is externally managed)" >&2
  if ! python3 -m venv .venv >/dev/null 2>&1; then
    apt-get install -y -qq --no-install-recommends python3-venv python3-dev python3-pip >/dev/null
    python3 -m venv .venv
  fi
  echo .venv/bin/python
}
PY=$(pick_python)
mkdir -p build
echo "$PY" > build/.python

if ! "$PY" - <<'PYEOF' 2>/dev/null
import importlib.metadata as md, sys
need = {"numpy": "1.22", "h5py": "3.8", "PyYAML": "6", "tqdm": "4.60", "pandas": "2",
        "pytest": "7", "pytest-xdist": "3.5", "av": "12", "pillow": "10", "pyarrow": "14",
        "scikit-build-core": "0.10", "pybind11": "2.12", "opencv-python-headless": "4.8",
        "matplotlib": "3.5", "scipy": "1.9", "pycocotools": "2.0",
        "torch": "2.13", "lightning": "2.2", "jsonargparse": "4.39", "dask": "2026.8",
        "distributed": "2026.8"}
def v(s): return tuple(int(x) for x in s.split(".")[:2] if x.isdigit())
for name, low in need.items():
    if v(md.version(name)) < v(low): sys.exit(1)
PYEOF
then
  echo "install-deps: pip install ${PIP_PACKAGES[*]}"
  "$PY" -m pip install -q "${PIP_PACKAGES[@]}"
fi
