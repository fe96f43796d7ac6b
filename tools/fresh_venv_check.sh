#!/usr/bin/env bash
# What a new user does: a fresh virtual environment, `pip install .` from a clean copy of
# this tree, import, generate a sample dataset, convert it. The build must not need the
# C++ test framework: doctest is made unfindable (CMAKE_DISABLE_FIND_PACKAGE_doctest), so
# any attempt to build the C++ tests fails this check. Needs the Debian packages of the
# README's "Install with pip" section and access to PyPI. Exit 0 when everything worked.
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

echo "fresh_venv_check: pip install . (no C++ tests, doctest unfindable)"
"$VPY" -m pip install -q \
  -Ccmake.define.CMAKE_DISABLE_FIND_PACKAGE_doctest=ON "$WORK/src"
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
echo "fresh_venv_check: OK"
