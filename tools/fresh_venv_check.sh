#!/usr/bin/env bash
# What a new user does: a fresh virtual environment, `pip install .` from a clean copy of
# this tree, import, generate a sample dataset, convert it. The build must not need the
# C++ test framework: doctest is made unfindable (CMAKE_DISABLE_FIND_PACKAGE_doctest), so
# any attempt to build the C++ tests fails this check. Then every extra is installed into
# a virtual environment of its own WITHOUT the system's site-packages (the test machines'
# Python has packages a user's venv lacks: scipy was one) and one real command per extra
# runs there, and every module of bsp_fast is imported: a module may fail only with the
# ImportError that names an extra this venv did not install. Needs the Debian packages of
# the README's "Install with pip" section and access to PyPI. Exit 0 when everything worked.
#
#   bash tools/fresh_venv_check.sh [PYTHON]     (default python3)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${1:-python3}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/bsp_fast-venv-XXXXXX")
trap 'rm -rf "$WORK"' EXIT

echo "fresh_venv_check: copying the tree (tracked and new files, no build/) to $WORK/src"
mkdir -p "$WORK/src"
git ls-files -z --cached --others --exclude-standard |
  while IFS= read -r -d '' f; do
    if [ -e "$f" ]; then cp --parents -- "$f" "$WORK/src/"; fi
  done

echo "fresh_venv_check: $PY -m venv"
"$PY" -m venv "$WORK/venv"
VPY="$WORK/venv/bin/python"
"$VPY" -m pip install -q --upgrade pip

echo "fresh_venv_check: pip wheel . and install it (no C++ tests, doctest unfindable)"
# one build: the wheel is then installed with each extra below
"$VPY" -m pip wheel -q --no-deps -w "$WORK/wheels" \
  -Ccmake.define.CMAKE_DISABLE_FIND_PACKAGE_doctest=ON "$WORK/src"
WHEEL=$(ls "$WORK"/wheels/bsp_fast-*.whl)
"$VPY" -m pip install -q "$WHEEL"
if grep -q "BSP_TESTS:BOOL=ON" "$WORK"/src/build/wheel/CMakeCache.txt 2>/dev/null; then
  echo "fresh_venv_check: the wheel build turned BSP_TESTS on" >&2
  exit 1
fi

echo "fresh_venv_check: import, bsp-synth sample, bsp-convert"
cd "$WORK"
# a file, not stdin: bsp-synth's worker processes are spawned and re-import __main__
cat > check.py <<'PYEOF'
import bsp_fast as bf

if __name__ == "__main__":
    print("bsp_fast", bf.__version__, "from", bf.__file__)
    bf.synth.generate("sample-ds", preset="sample", seed=1, progress=False)
    report = bf.convert("sample-ds", "clips.h5", verify=True, progress=False)
    splits = report["splits"]
    print({name: (s["clips"], s["not-crossing"], s["crossing"]) for name, s in splits.items()})
    assert all(s["clips"] > 0 for s in splits.values()), "an empty split"
    assert not report["verify_failed"], report["verify_failed"]
    try:
        import torch  # noqa: F401
    except ImportError:
        try:
            from bsp_fast.data import ClipDataset  # noqa: F401
        except ImportError as exc:
            assert "bsp_fast[torch]" in str(exc), exc
            print("without torch: ImportError names the extra")
PYEOF
"$VPY" check.py
"$WORK/venv/bin/bsp-convert" --help >/dev/null
"$WORK/venv/bin/bsp-interop" export coco clips.h5 coco.json >/dev/null

# Every module imported. An ImportError is allowed only for a module of an extra that this
# venv did not install (argv[1]: the installed extras, comma-separated): the message names
# that extra, or the missing module is one bsp_fast._extras assigns to it. A module missing
# while its extra is installed (scipy was one) fails.
cat > imports.py <<'PYEOF'
import importlib, pkgutil, re, sys
import bsp_fast
from bsp_fast._extras import EXTRAS

installed = set(filter(None, sys.argv[1].split(",")))
bad, skipped = [], 0
for m in pkgutil.walk_packages(bsp_fast.__path__, "bsp_fast.", onerror=lambda name: None):
    if m.name.endswith("__main__"):
        continue
    try:
        importlib.import_module(m.name)
    except ImportError as exc:
        named = re.search(r"bsp_fast\[(\w+)\]", str(exc))
        extra = named.group(1) if named else EXTRAS.get((exc.name or "").split(".")[0])
        if extra is not None and extra not in installed:
            skipped += 1
            continue
        bad.append(f"{m.name}: {type(exc).__name__}: {exc}")
print(f"imports with extras {sorted(installed) or 'none'}: {len(bad)} failed, "
      f"{skipped} need an extra not installed here")
sys.exit("\n".join(bad) if bad else 0)
PYEOF
"$VPY" imports.py ""

# extra_venv NAME EXTRAS: a venv without system site-packages, the wheel with EXTRAS
extra_venv() {
  echo "fresh_venv_check: venv with bsp_fast[$2]"
  "$PY" -m venv "$WORK/venv-$1"
  "$WORK/venv-$1/bin/python" -m pip install -q "$WHEEL[$2]"
  "$WORK/venv-$1/bin/python" imports.py "$2"
}
# preview and distributed, without torch: a contact sheet, a conversion on a Dask cluster;
# beside the torch venv (both mostly pip's unpacking, one core each: about 45 s saved)
(  # set -e holds in the subshell too
  extra_venv viewdask preview,distributed
  "$WORK/venv-viewdask/bin/bsp-preview" clips clips.h5 --n 4 --out grid.png >/dev/null
  test -s grid.png
  "$WORK/venv-viewdask/bin/bsp-convert" sample-ds clips-dask.h5 --scheduler dask --quiet
  test -s clips-dask.h5
) > viewdask.log 2>&1 &
VIEWDASK=$!
# torch (the training side; scipy for the intervals): a seeded smoke table, two seeds
extra_venv torch torch
"$WORK/venv-torch/bin/bsp-reproduce" autoencoder --data sample-ds --budget smoke --seeds 2 \
  --out runs-torch > reproduce.log 2>&1 || { cat reproduce.log >&2; exit 1; }
test -s runs-torch/autoencoder-smoke/results.md
if ! wait "$VIEWDASK"; then
  cat viewdask.log >&2
  echo "fresh_venv_check: the preview,distributed venv failed (above)" >&2
  exit 1
fi
cat viewdask.log
echo "fresh_venv_check: OK"
