#!/usr/bin/env bash
# #36's training benchmarks on a lent GPU machine (docs/performance.md, "Another CPU and a
# GPU"): its CPU is a second kind of CPU, its GPU the accelerator the full budgets name.
#
#   bash benchmarks/gpu_check.sh prepare DIR   # here, with the C++ core built ($PYTHON)
#   bash benchmarks/gpu_check.sh run DIR OUT   # there (DIR carried along)
#
# That machine has Python and PyTorch but not the Debian libraries the C++ core links, and
# the core is not in the training path: `prepare` writes a stand-in for bsp_fast._core that
# holds the core's constants (joint names, parents, ...) and raises on any call, the
# benchmarks' fixture clip files (which the core's kinematics makes) and a jsonargparse
# wheel (bsp-train's parser, not in that image). `run` times, in one pass:
#   - on 11 of its CPU cores, one thread per process: the precision probe of every model,
#     the pose networks' activation layouts, and the plain loop against bsp-train in
#     float32 and bf16 for the six fast models (PoseFormer left out: minutes per mode);
#   - on the GPU (cores 0-3 reserved for it): the probe's float32 / bf16 step ratio per
#     model and the plain loop against bsp-train.
set -euo pipefail
cmd=$1 dir=$2
cd "$(dirname "$0")/.."
if [ "$cmd" = prepare ]; then
  mkdir -p "$dir/bsp_fast" "$dir/fixtures" "$dir/wheels"
  PYTHONPATH=python:benchmarks "${PYTHON:-python3}" - "$dir" <<'EOF'
import hashlib, os, sys
import numpy as np
from bsp_fast import _core
import bench_precision_probe as P, bench_train_loop as L
d = sys.argv[1]
consts = {n: getattr(_core, n) for n in dir(_core)
          if not n.startswith("__") and not callable(getattr(_core, n))}
with open(os.path.join(d, "bsp_fast", "_core.py"), "w") as f:
    f.write('"""Stand-in for the C++ core where it is not built (benchmarks/gpu_check.sh)."""\n'
            "import hashlib\n\nimport numpy as np\n\n\nclass Error(Exception):\n    pass\n\n\n"
            "CsvParseError = VideoDecodeError = VideoEncodeError = ApngError = Error\n"
            "Hdf5Error = MotionError = Error\n\n\n"
            "def set_num_threads(n):\n    pass\n\n\ndef num_threads():\n    return 1\n\n\n"
            "def library_versions():\n    return []\n\n\n")
    f.writelines(f"{n} = {v!r}\n" for n, v in consts.items())
    # what building the models asks of the core (forward kinematics and rotation matrices
    # of the reference T-poses): the core's own answers, recorded here by the function and
    # its arguments' bytes, looked up there; any other call raises
    from bsp_fast import geometry, models, skeleton
    calls, real = {}, geometry._core

    key_src = (
        "def key_of(name, args):\n"
        "    h = hashlib.sha1(name.encode())\n"
        "    for a in args:\n"
        "        h.update(np.ascontiguousarray(a).tobytes() + repr(np.shape(a)).encode()\n"
        "                 if isinstance(a, np.ndarray) else repr(a).encode())\n"
        "    return h.hexdigest()\n")
    exec(key_src)

    class Recorder:
        def __getattr__(self, name):
            fn = getattr(real, name)
            if not callable(fn) or isinstance(fn, type):
                return fn

            def recorded(*args):
                out = fn(*args)
                if isinstance(out, np.ndarray):
                    calls[key_of(name, args)] = (out.shape, str(out.dtype), out.ravel().tolist())
                return out
            return recorded
    geometry._core = Recorder()
    for stem in sorted(set(skeleton.MODELS.values())):
        skeleton.hips_neck_length(*next(k for k, v in skeleton.MODELS.items() if v == stem))
    for name in {m for m, *_ in P.MODELS} | {m for m, *_ in L.MODELS}:
        models.create(*name.split("/"))
    geometry._core = real
    f.write(f"\n_CALLS = {calls!r}\n\n\n")
    f.write(key_src)
    f.write("\n\nclass _Absent(type):\n    def __getattr__(cls, name):\n        return cls\n\n"
            "    def __call__(cls, *a, **k):\n"
            "        raise RuntimeError(f'bsp_fast._core.{cls.__name__}: no C++ core here')\n\n\n"
            "def __getattr__(name):\n    if name[:1].isupper():\n"
            "        return _Absent(name, (), {})\n\n    def absent(*args):\n"
            "        import numpy as np\n        hit = _CALLS.get(key_of(name, args))\n"
            "        if hit is None:\n"
            "            raise RuntimeError(f'bsp_fast._core.{name}: no C++ core here')\n"
            "        return np.array(hit[2], dtype=hit[1]).reshape(hit[0])\n"
            "    return absent\n")
fx = os.path.join(d, "fixtures")
for name, batch, length, _ in L.MODELS:  # what `run` passes: --train-clips 512
    L.clip_file(fx, name, batch, length, 512)
for name, batch, length in P.MODELS:
    P.fixture(fx, name, batch, length)
EOF
  # identical files (same generator arguments) as hard links: tar stores them once
  (cd "$dir/fixtures" && md5sum ./*.h5 | sort | awk '$1 == p {print f, $2; next} {p = $1; f = $2}' |
     while read -r a b; do ln -f "$a" "$b"; done)
  tar czf "$dir/fixtures.tar.gz" -C "$dir" fixtures && rm -rf "$dir/fixtures"
  [ -n "${GPU_CHECK_NO_WHEEL:-}" ] && exit 0  # (the tests: no network needed)
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp -d "$dir/wheels" "jsonargparse==$(python3 -c 'import jsonargparse as j; print(j.__version__)')" \
    || echo "gpu_check: no jsonargparse wheel (offline?): the bsp-train rows will fail there" >&2
  exit 0
fi

out=$3
mkdir -p "$out" /tmp/fx
tar xzf "$dir/fixtures.tar.gz" -C /tmp/fx
python3 -m pip install -q --no-index --no-deps --target /tmp/site "$dir"/wheels/*.whl || true
export PYTHONPATH=/tmp/site:python:$dir PYTHONUNBUFFERED=1
FX=/tmp/fx/fixtures
pin() {  # taskset where util-linux is there
  if command -v taskset >/dev/null; then taskset -c "$@"; else shift; "$@"; fi
}
{
  nvidia-smi -L; grep -m1 "model name" /proc/cpuinfo; nproc
  grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|avx512f|avx512_bf16|amx_bf16|amx_tile)$' | tr '\n' ' '; echo
  python3 -c "import torch, lightning; print('torch', torch.__version__, 'lightning', lightning.__version__)"
  cat /proc/loadavg
} > "$out/machine.txt" 2>&1
# the CPU side, one core each, beside the GPU's cores
pin 4 timeout 300 python3 benchmarks/bench_precision_probe.py --fixtures $FX \
  > "$out/probe_cpu.md" 2>&1 &
pin 5 timeout 300 python3 benchmarks/bench_memory_format.py --steps 6 \
  > "$out/layout_cpu.md" 2>&1 &
core=6
for m in lifting/lstm classification/lstm lifting/lstm_relative_rot classification/pedestrian_graph \
         lifting/baseline_3d autoencoder/simple_transformer; do
  pin $core timeout 400 python3 benchmarks/bench_train_loop.py --models $m --fixtures $FX \
    --train-clips 512 --epochs 2 --modes eager32 eager_bf16 bsp_train32 bsp_train_bf16 \
    --json "$out/loop_cpu.jsonl" > "/tmp/loop_cpu_${m//\//_}.md" 2>&1 &
  core=$((core + 1))
done
# the GPU side, in turn
pin 0-3 timeout 150 python3 benchmarks/bench_precision_probe.py --device cuda \
  --fixtures $FX > "$out/probe_gpu.md" 2>&1 || echo "probe_gpu exit $?" >> "$out/probe_gpu.md"
pin 0-3 timeout 240 python3 benchmarks/bench_train_loop.py --accelerator gpu --fixtures $FX \
  --train-clips 512 --epochs 4 --modes eager32 eager_bf16 bsp_train_bf16 \
  --json "$out/loop_gpu.jsonl" > "$out/loop_gpu.md" 2>&1 || echo "loop_gpu exit $?" >> "$out/loop_gpu.md"
wait || true
cat /tmp/loop_cpu_*.md > "$out/loop_cpu.md"
cat /proc/loadavg >> "$out/machine.txt"
