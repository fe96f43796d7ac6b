#!/usr/bin/env bash
# The loaders before and after a change, side by side in one run: bench_loader.py on one
# fixture with the Python package of REV (default HEAD) and of the working tree,
# interleaved REV, tree, REV, tree, with the load average before each run.
#
#   bash benchmarks/ab_loader.sh [REV] [OUT_DIR]       (default HEAD, bench-ab)
set -euo pipefail
cd "$(dirname "$0")/.."
REV=${1:-HEAD}
OUT=${2:-bench-ab}
PY=$(cat build/.python 2>/dev/null || echo python3)
mkdir -p "$OUT"
OLD=$(mktemp -d)
trap 'rm -rf "$OLD"' EXIT
git archive "$REV" python benchmarks | tar -x -C "$OLD"
# the compiled core is the same for both (this compares Python code)
CORE=$("$PY" -c 'import bsp_fast._native as n, os; print(os.path.dirname(n.core.__file__))')
cp "$CORE"/_core*.so "$OLD/python/bsp_fast/"
F="$OUT/fixture.h5"
[ -f "$F" ] || "$PY" -c "from bsp_fast.data.testing import write_clip_file as w; \
w('$F', clips=(20000, 100, 100), clip_length=30, seed=0, rotations=False)"
grep -o -w -E 'avx2|avx512f|avx512_bf16|amx_tile' /proc/cpuinfo | sort -u | tr '\n' ' '
echo
for rep in 1 2; do
  for side in before after; do
    if [ $side = before ]; then PP=$OLD/python; B=$OLD/benchmarks/bench_loader.py
    else PP=$PWD/python; B=benchmarks/bench_loader.py; fi
    echo "== $side rep $rep load $(cut -d' ' -f1-3 /proc/loadavg)"
    PYTHONPATH=$PP "$PY" "$B" --h5 "$F" --workers 0 --repeat 2 --naive-limit 500 \
      --pose-clips 512 --json "$OUT/$side-$rep.json"
  done
done
echo "== end load $(cut -d' ' -f1-3 /proc/loadavg)"
