#!/usr/bin/env bash
# The pose table's rows on a lent GPU machine (docs/performance.md, "pose_temporal on a
# GPU"): does bsp-reproduce train them there end to end (--set accelerator=gpu), how long
# does a run take with 15 at once on the one GPU, and does a seed give the same metrics twice?
#
#   bash benchmarks/gpu_pose_check.sh prepare DIR H5   # here: DIR/ gets the stand-in core
#                                                      # (gpu_check.sh prepare), the wheel
#                                                      # and H5 (a converted pose file), xz'd
#   bash benchmarks/gpu_pose_check.sh run DIR OUT      # there (DIR carried along)
#
# H5 is a small pose-estimation conversion (bsp-synth --preset sample, converted with the
# pose table's quick settings): the table's own data (--preset medium, 1.0 GB converted,
# about 2.2x smaller under xz) cannot travel to that machine (64 MiB per call), and the
# C++ core that makes it cannot be built there (no Debian libraries). So this measures the
# pipeline and the time per update, not the table's numbers.
set -euo pipefail
cmd=$1 dir=$2
cd "$(dirname "$0")/.."
if [ "$cmd" = prepare ]; then
  h5=$3
  bash benchmarks/gpu_check.sh prepare "$dir"
  rm -f "$dir/fixtures.tar.gz"  # gpu_check's own fixtures: not used here
  xz -T2 -6 -c "$h5" > "$dir/pose.h5.xz"
  exit 0
fi

out=$3
mkdir -p "$out" /tmp/pose
xz -d -c "$dir/pose.h5.xz" > /tmp/pose/sample.h5
python3 -m pip install -q --no-index --no-deps --target /tmp/site "$dir"/wheels/*.whl
export PYTHONPATH=/tmp/site:python:$dir PYTHONUNBUFFERED=1
{
  nvidia-smi -L; grep -m1 "model name" /proc/cpuinfo; nproc
  grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|avx512f|avx512_bf16|amx_bf16|amx_tile)$' | tr '\n' ' '; echo
  python3 -c "import torch, lightning; print('torch', torch.__version__, 'lightning', lightning.__version__)"
  cat /proc/loadavg
} > "$out/machine.txt" 2>&1
# 1. does torch's deterministic mode (bsp-train's deterministic=True) refuse
# pose_temporal's bilinear upsampling backward on CUDA, as earlier torch releases did?
python3 - > "$out/deterministic.txt" 2>&1 <<'EOF' || true
import torch, torch.nn.functional as F
torch.use_deterministic_algorithms(True)
x = torch.randn(2, 3, 8, 8, device="cuda", requires_grad=True)
try:
    F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False).sum().backward()
    print("bilinear backward under deterministic=True: ran")
except RuntimeError as exc:
    print("bilinear backward under deterministic=True: RuntimeError:", str(exc).splitlines()[0])
EOF
rows=pose_temporal_heatmap_dark,pose_temporal_no_image_augment,pose_temporal_w32_long
run() {  # OUTDIR SEEDS JOBS ROWS: the quick budget's rows on the GPU, timed
  local t0=$SECONDS
  timeout 150 python3 -m bsp_fast reproduce pose_estimation --data /tmp/pose/sample.h5 \
    --budget quick --rows "$4" --seeds "$2" --jobs "$3" --set accelerator=gpu --out "$1" \
    > "$1.log" 2>&1 || echo "exit $?" >> "$1.log"
  echo "$1: $((SECONDS - t0)) s wall for the call" >> "$out/wall.txt"
}
# 2. one run alone, then the three rows x 5 seeds at once (15 processes, one GPU)
run /tmp/alone 1 1 pose_temporal_w32_long
run /tmp/all 5 15 "$rows"
# 3. the same runs twice at once (two rows, one seed, two calls side by side): are a GPU
# run's metrics a function of its seed, as on a CPU?
for o in a b; do
  timeout 150 python3 -m bsp_fast reproduce pose_estimation --data /tmp/pose/sample.h5 \
    --budget quick --rows pose_temporal_no_image_augment,pose_temporal_heatmap_dark --seeds 1 \
    --jobs 2 --set accelerator=gpu --out /tmp/twice_$o > /tmp/twice_$o.log 2>&1 &
done
wait
python3 - > "$out/twice.txt" 2>&1 <<'EOF' || true
import glob, json
for row in ("pose_temporal_no_image_augment", "pose_temporal_heatmap_dark"):
    ms = [json.load(open(p)) for p in sorted(glob.glob(
        f"/tmp/twice_[ab]/pose_estimation-quick/{row}/**/metrics.json", recursive=True))]
    same = [ms[0][k] == ms[1][k] for k in ("val", "test")]
    noisy = [open(p).read() for p in sorted(glob.glob(
        f"/tmp/twice_[ab]/pose_estimation-quick/{row}/**/test_box_noise.json", recursive=True))]
    print(row, ms[0]["precision"], "val identical" if same[0] else "val differ",
          "test identical" if same[1] else "test differ",
          "noisy-box test identical" if noisy[0] == noisy[1] else "noisy-box test differ")
EOF
cat /proc/loadavg >> "$out/machine.txt"
python3 - "$out" <<'EOF'
import csv, glob, json, os, sys
rows = []
for path in sorted(glob.glob("/tmp/*/pose_estimation-quick/*/seed-*/metrics.json")):
    m = json.load(open(path))
    rows.append({"run": path.split("/pose_estimation-quick/")[0] + ":" + "/".join(path.split("/")[-3:-1]),
                 "precision": m.get("precision"), "epochs": m.get("epochs"),
                 "seconds": m.get("seconds"), "steps": max(
                     (int(r["step"]) for f in glob.glob(os.path.dirname(path) + "/logs/*/metrics.csv")
                      for r in csv.DictReader(open(f)) if r.get("step")), default=None),
                 "pck_0.05": (m.get("test") or {}).get("pck_0.05")})
with open(sys.argv[1] + "/runs.jsonl", "w") as f:
    f.writelines(json.dumps(r) + "\n" for r in rows)
EOF
tail -n 40 /tmp/all.log > "$out/all_tail.log"; tail -n 20 /tmp/alone.log > "$out/alone_tail.log"
cp /tmp/all/pose_estimation-quick/results.md "$out/results_sample.md" 2>/dev/null || true
