#!/usr/bin/env bash
# The repaired manylinux wheel (tools/build_wheel.sh, docs/install.md) on a machine with
# Python and glibc only: no compiler, no CMake, none of the -dev packages, none of the
# libraries the wheel vendors. Exit 0 when everything worked.
#
#   bash tools/wheel_check.sh [WHEEL] [PYTHON]
#
# WHEEL: a repaired wheel to check as it is, or a plain linux_x86_64 one (pip wheel .) to
# repair first; without it the wheel is built with tools/build_wheel.sh, which reuses
# build/wheel (after `make test` it compiles nothing). PYTHON: the one the wheel is for
# (default: build/.python, the one make deps chose).
#
# 1. `auditwheel show`: a manylinux tag, nothing left to graft; every DT_NEEDED of every
#    ELF file in the wheel is in the wheel or one of glibc's, libstdc++, libgcc_s.
# 2. The machine without compilers and libraries, emulated in a private mount namespace
#    (unshare; where it is not permitted, only PATH and CC/CXX are stripped, and this says
#    so): /usr/include, gcc's and clang's directories and CMake's modules are empty, and
#    every shared library of the loader's directories is an empty file except glibc's,
#    libstdc++, libgcc_s and those the Python interpreter, its extension modules and the
#    few shell tools used here load. PATH holds those tools and the venv, CC=CXX=/bin/false.
# 3. There: a virtual environment without system site-packages, `pip install --only-binary
#    :all:` of the wheel (timed; pip's log must show no build), then from outside the
#    source tree bsp-synth (sample preset), bsp-convert --verify, `import bsp_fast`, h5py
#    and bsp_fast in one process both ways round (a conversion after h5py loaded its own
#    libhdf5, h5py reading every dataset the core wrote), then the extras of
#    WHEEL_CHECK_EXTRAS (default: preview, whose opencv wheel vendors its own OpenCV and
#    FFmpeg) installed and, for each extra installed, bsp_fast imported with its modules
#    (preview: a bsp-preview contact sheet). Where torch is installed (WHEEL_CHECK_EXTRAS
#    naming `torch`), a one-epoch bsp-train on the sample.
#
# WHEEL_CHECK_SHOW=FILE: `auditwheel show` of WHEEL as saved by its build, read instead of
# running it again. WHEEL_CHECK_SUMMARY=FILE: the measurements (wheel size, install times,
# venv sizes, the torch installed) as KEY=VALUE lines in FILE, for tools/wheel_matrix.sh.
set -euo pipefail
GIVEN=${1:+$(readlink -f "$1")}
cd "$(dirname "$0")/.."
PY=${2:-$(cat build/.python 2>/dev/null || echo python3)}
PYEXE=$("$PY" -c 'import os, sys; print(os.path.realpath(sys.executable))')
EXTRAS=${WHEEL_CHECK_EXTRAS-preview}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/bsp_fast-wheel-XXXXXX")
trap 'rm -rf "$WORK"' EXIT
t0=$SECONDS

# ---------------------------------------------------------------- the wheel
if [ -z "$GIVEN" ]; then
  bash tools/build_wheel.sh "$PY" | tee "$WORK/build.log"
elif [[ "$(basename "$GIVEN")" == *manylinux* ]]; then
  bash tools/build_wheel.sh --tools "$PY" >/dev/null
  echo "$GIVEN" > "$WORK/build.log"
else
  bash tools/build_wheel.sh --repair "$GIVEN" "$PY" | tee "$WORK/build.log"
fi
WHEEL=$(readlink -f "$(tail -n 1 "$WORK/build.log")")
TOOLS=$(pwd)/build/wheel-tools
t_built=$SECONDS

# ---------------------------------------------------------------- 1. auditwheel show
# (WHEEL_CHECK_SHOW: tools/wheel_matrix.sh passes the one tools/build_wheels.sh saved)
if [ -n "${WHEEL_CHECK_SHOW:-}" ]; then
  cp "$WHEEL_CHECK_SHOW" "$WORK/show.txt"
else
  "$TOOLS/bin/auditwheel" show "$WHEEL" > "$WORK/show.txt" 2>&1
fi
echo "wheel_check: auditwheel show $(basename "$WHEEL"):"
sed -n -e '/is consistent/,/^$/p' -e '/This constrains/,/^$/p' "$WORK/show.txt"
"$TOOLS/bin/python" - "$WHEEL" "$WORK/show.txt" "$WORK/summary" <<'PYEOF'
import io, os, re, sys, zipfile
from elftools.elf.dynamic import DynamicSection
from elftools.elf.elffile import ELFFile

# What the wheel may take from the machine: glibc, libstdc++, libgcc_s.
SYSTEM = re.compile(r"(libc|libm|libmvec|libpthread|libdl|librt|libresolv|libutil|libanl|"
                    r"ld-linux-x86-64|libstdc\+\+|libgcc_s)\.so\.\d+$")
# auditwheel's verdict: the wheel's libraries and symbol versions fit a manylinux policy
show = " ".join(open(sys.argv[2]).read().split())
tag = re.search(r'is consistent with the following platform tag: "([^"]+)"', show)
if not tag or not tag.group(1).startswith("manylinux_") or "eliminated" in show:
    sys.exit(f"wheel_check: auditwheel show: not a manylinux wheel\n{show}")
z = zipfile.ZipFile(sys.argv[1])
names = z.namelist()
inside = {n.rsplit("/", 1)[-1] for n in names}
vendored = [i for i in z.infolist() if i.filename.startswith("bsp_fast.libs/") and not i.is_dir()]
with open(sys.argv[3], "a") as summary:
    print(f"wheel={sys.argv[1].rsplit('/', 1)[-1]}\nplatform={tag.group(1)}\n"
          f"wheel_mb={os.path.getsize(sys.argv[1]) / 1e6:.1f}\nlibraries={len(vendored)}",
          file=summary)
external = {}
for name in names:
    data = z.read(name)
    if data[:4] != b"\x7fELF":
        continue
    for section in ELFFile(io.BytesIO(data)).iter_sections():
        if isinstance(section, DynamicSection):
            for tag in section.iter_tags("DT_NEEDED"):
                if tag.needed not in inside:
                    external.setdefault(tag.needed, set()).add(name.rsplit("/", 1)[-1])
print(f"wheel_check: {len(vendored)} libraries vendored "
      f"({sum(i.file_size for i in vendored) / 1e6:.0f} MB unpacked); from the system: "
      f"{' '.join(sorted(external))}")
undeclared = {lib: users for lib, users in external.items() if not SYSTEM.match(lib)}
for lib, users in sorted(undeclared.items()):
    print(f"wheel_check: {lib} is neither in the wheel nor glibc's, needed by "
          f"{', '.join(sorted(users))}", file=sys.stderr)
sys.exit(1 if undeclared else 0)
PYEOF

# ---------------------------------------------------------------- 2. the bare machine
mkdir -p "$WORK/bin" "$WORK/run" "$WORK/empty-dir"
: > "$WORK/empty-file"
for tool in bash tail du; do
  ln -s "$(command -v "$tool")" "$WORK/bin/$tool"
done
cat > "$WORK/bare.py" <<'PYEOF'
"""bare.py WORK PYEXE CMD...: CMD in a private mount namespace where the compilers, headers
and all shared libraries but glibc's, libstdc++, libgcc_s and those PYEXE, its extension
modules and WORK/bin's tools load are gone (empty). Without permission for unshare, CMD
runs as it is, with BARE_MACHINE=0 in its environment."""
import ctypes, glob, os, re, shutil, subprocess, sys

work, pyexe, *cmd = sys.argv[1:]
tools_path = os.environ.pop("BARE_TOOLS_PATH")  # where ldd and ldconfig are
libc = ctypes.CDLL(None, use_errno=True)
CLONE_NEWNS, MS_BIND, MS_REC, MS_PRIVATE = 0x20000, 4096, 16384, 1 << 18


def mount(source, target, flags):
    if libc.mount(source and source.encode(), target.encode(), None, flags, None) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err), target)


def ldd(paths):
    found = set()
    for path in paths:
        out = subprocess.run([shutil.which("ldd", path=tools_path), path],
                             capture_output=True, text=True).stdout
        found.update(os.path.realpath(m) for m in re.findall(r"(/\S+) \(0x", out))
    return found


dirs = {"/lib/x86_64-linux-gnu", "/usr/lib/x86_64-linux-gnu", "/lib64", "/usr/lib64"}
out = subprocess.run([shutil.which("ldconfig", path=tools_path), "-p"],
                     capture_output=True, text=True).stdout
dirs.update(os.path.dirname(p) for p in re.findall(r"=> (/\S+)", out))
dirs = {os.path.realpath(d) for d in dirs if os.path.isdir(d)}
dynload = [p for p in glob.glob(os.path.join(
    os.path.dirname(os.path.dirname(pyexe)), "lib", "python3*", "lib-dynload", "*.so"))
    if "_tkinter" not in p]
tools = [os.path.realpath(p) for p in glob.glob(os.path.join(work, "bin", "*"))]
keep = ldd([pyexe, *dynload, *tools])
system = re.compile(r"(libc|libm|libmvec|libpthread|libdl|librt|libresolv|libutil|libanl|"
                    r"libnss_\w+|libthread_db|ld-linux-x86-64|libstdc\+\+|libgcc_s)\.so")
hide = set()
for d in dirs:
    for f in glob.glob(os.path.join(d, "*.so*")):
        real = os.path.realpath(f)
        if not os.path.isfile(real):
            continue
        if system.match(os.path.basename(f)) or system.match(os.path.basename(real)):
            keep.add(real)
        else:
            hide.add(real)
hide -= keep
env = dict(os.environ, BARE_MACHINE="1")
if libc.unshare(CLONE_NEWNS) != 0:
    print(f"wheel_check: no private mount namespace ({os.strerror(ctypes.get_errno())}): "
          "the libraries and headers of this machine stay visible; PATH and CC/CXX only",
          flush=True)
    env["BARE_MACHINE"] = "0"
else:
    mount(None, "/", MS_REC | MS_PRIVATE)
    gone = [d for d in ["/usr/include", "/usr/local/include", "/usr/lib/gcc", "/usr/libexec/gcc",
                        *glob.glob("/usr/lib/llvm-*"), *glob.glob("/usr/share/cmake*")]
            if os.path.isdir(d)]
    for f in sorted(hide):  # (before the directories: some are under /usr/lib/llvm-*)
        mount(os.path.join(work, "empty-file"), f, MS_BIND)
    for d in gone:
        mount(os.path.join(work, "empty-dir"), d, MS_BIND)
    print(f"wheel_check: bare machine: {len(hide)} shared libraries emptied, {len(keep)} "
          f"kept (glibc, libstdc++, libgcc_s, Python's); {', '.join(gone)} empty", flush=True)
os.execve(cmd[0], cmd, env)
PYEOF

cat > "$WORK/run/h5.py" <<'PYEOF'
"""h5py and bsp_fast in one process (argv[1]: which is imported first): a conversion after
both libhdf5 copies are loaded, then h5py reads every dataset the core wrote."""
import sys

first = sys.argv[1]
if first == "h5py":
    import h5py
    import bsp_fast as bf
else:
    import bsp_fast as bf
    import h5py


def read_all(path):
    arrays = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: arrays.__setitem__(name, obj[()])
                     if isinstance(obj, h5py.Dataset) else None)
    return arrays


if __name__ == "__main__":
    report = bf.convert("sample-ds", f"clips-{first}.h5", verify=True, progress=False)
    assert not report["verify_failed"], report["verify_failed"]
    mine, cli = read_all(f"clips-{first}.h5"), read_all("clips.h5")
    assert mine and mine.keys() == cli.keys(), (sorted(mine), sorted(cli))
    n = sum(v.size for v in mine.values() if hasattr(v, "size"))
    print(f"wheel_check: {first} first: {len(mine)} datasets, {n} values read with h5py "
          f"{h5py.__version__} (HDF5 {h5py.version.hdf5_version}); the core's HDF5 "
          f"{bf._core.library_versions()['hdf5']}, from {bf.__file__}")
PYEOF

cat > "$WORK/run/extras.py" <<'PYEOF'
"""For every extra of the wheel whose requirements are all installed, bsp_fast and what
the extra adds are imported in one process."""
import importlib, importlib.metadata as md, re, sys

import bsp_fast  # noqa: F401

MODULES = {"torch": ["torch", "bsp_fast.data", "bsp_fast.training.train"],
           "preview": ["cv2", "matplotlib", "bsp_fast.preview.cli"],
           "distributed": ["dask.distributed", "bsp_fast.dask_cluster"],
           "loggers": ["tensorboard", "wandb"],
           "test": ["pytest", "xdist", "pandas", "av", "PIL", "pyarrow"]}
extras = {}
for req in md.requires("bsp_fast") or []:
    m = re.match(r"([A-Za-z0-9_.\-]+).*extra == \"(\w+)\"", req)
    if m:
        extras.setdefault(m.group(2), []).append(m.group(1))
installed = []
for extra, reqs in sorted(extras.items()):
    try:
        for r in reqs:
            md.distribution(r)
    except md.PackageNotFoundError:
        continue
    for module in MODULES.get(extra, []):
        importlib.import_module(module)
    installed.append(extra)
print(f"wheel_check: import bsp_fast with the extras installed here: "
      f"{', '.join(installed) or 'none'} ({', '.join(sorted(extras))} declared)")
PYEOF

cat > "$WORK/payload.sh" <<'SHEOF'
set -euo pipefail
cd "$WORK/run"
for tool in cc c++ gcc g++ clang clang++ cmake ninja make ld; do
  if command -v "$tool" >/dev/null; then echo "wheel_check: $tool is on PATH" >&2; exit 1; fi
done
if [ "$BARE_MACHINE" = 1 ] && { [ -e /usr/include/stdio.h ] || compgen -G '/usr/lib/gcc/*'; }; then
  echo "wheel_check: headers or gcc still visible" >&2; exit 1
fi
t=$EPOCHREALTIME
"$PYEXE" -m venv "$WORK/venv"
t_venv=$EPOCHREALTIME
# --only-binary :all: : an sdist anywhere (a dependency without a wheel) fails here
"$WORK/venv/bin/python" -m pip install --only-binary :all: "$WHEEL" > pip.log 2>&1 ||
  { tail -n 30 pip.log >&2; exit 1; }
t_pip=$EPOCHREALTIME
# pip's log: nothing built (no sdist, no setup.py, no build backend), what was installed
installed=$("$PYEXE" - pip.log <<'PYEOF'
import re, sys
log = open(sys.argv[1]).read()
built = re.findall(r"(?im)^.*(building wheel|running setup\.py|build_ext|preparing metadata"
                   r"|installing build dependencies).*$", log)
if built:
    sys.exit("wheel_check: pip built something:\n" + "\n".join(built))
print(len(re.search(r"Successfully installed (.*)", log).group(1).split()))
PYEOF
)
venv_mib=$(du -sm "$WORK/venv")
venv_mib=${venv_mib%%[[:space:]]*}
summary python "$("$PYEXE" -c 'import platform; print(platform.python_version())')"
summary venv_s "$(bc_ "$t_venv" "$t")"
summary install_s "$(bc_ "$t_pip" "$t_venv")"
summary packages "$installed"
summary venv_mib "$venv_mib"
export PATH="$WORK/venv/bin:$PATH"
echo "wheel_check: python -m venv $(bc_ "$t_venv" "$t") s, pip install the wheel" \
     "$(bc_ "$t_pip" "$t_venv") s, nothing built ($installed packages, the venv $venv_mib MiB)"
t=$EPOCHREALTIME
bsp-synth sample-ds --preset sample --seed 1 --quiet
t_synth=$EPOCHREALTIME
bsp-convert sample-ds clips.h5 --verify --quiet
python -c 'import bsp_fast'
echo "wheel_check: bsp-synth --preset sample $(bc_ "$t_synth" "$t") s, bsp-convert --verify" \
     "$(bc_ "$EPOCHREALTIME" "$t_synth") s (in $PWD)"
summary synth_s "$(bc_ "$t_synth" "$t")"
summary convert_s "$(bc_ "$EPOCHREALTIME" "$t_synth")"
python h5.py h5py
python h5.py bsp_fast
if [ -n "$EXTRAS" ]; then
  t=$EPOCHREALTIME
  python -m pip install --only-binary :all: "$WHEEL[$EXTRAS]" > pip-extras.log 2>&1 ||
    { tail -n 30 pip-extras.log >&2; exit 1; }
  summary extras_s "$(bc_ "$EPOCHREALTIME" "$t")"
  venv_mib=$(du -sm "$WORK/venv")
  summary extras_venv_mib "${venv_mib%%[[:space:]]*}"
  echo "wheel_check: pip install the wheel's [$EXTRAS] $(bc_ "$EPOCHREALTIME" "$t") s," \
       "the venv ${venv_mib%%[[:space:]]*} MiB"
fi
python extras.py
if torch=$(python -c 'import torch; print(torch.__version__)' 2>/dev/null); then
  # One epoch of the demo's model (make demo) on the sample just converted: torch, Lightning
  # and the wheel's core in one process, a checkpoint written.
  t=$EPOCHREALTIME
  bsp-train lifting lstm --data sample-ds --clip-length 16 --clip-offset 4 --epochs 1 \
    --batch-size 8 --lr 1e-3 --seed 1 --threads 1 --out runs/one-epoch --force --quiet
  test -s runs/one-epoch/checkpoints/last.ckpt
  summary torch "$torch"
  summary train_s "$(bc_ "$EPOCHREALTIME" "$t")"
  echo "wheel_check: bsp-train one epoch with torch $torch $(bc_ "$EPOCHREALTIME" "$t") s"
fi
if python -c 'import cv2' 2>/dev/null; then
  bsp-preview clips clips.h5 --n 4 --out grid.png >/dev/null
  test -s grid.png
  echo "wheel_check: bsp-preview (cv2's own OpenCV and FFmpeg beside the wheel's) OK"
fi
SHEOF

echo "wheel_check: install and run on a bare machine (extras: ${EXTRAS:-none})"
# pip's settings and proxies of this environment go in (PyPI as pip reaches it here)
mapfile -t PASS < <(env | grep -E \
  '^(PIP_[A-Z_]+|https?_proxy|HTTPS?_PROXY|no_proxy|NO_PROXY|SSL_CERT_[A-Z]+)=' || true)
# bc_ END START: seconds between two $EPOCHREALTIME values, one decimal, in bash alone
env -i HOME="$HOME" LANG=C.UTF-8 PATH="$WORK/bin" CC=/bin/false CXX=/bin/false \
  BARE_TOOLS_PATH="$PATH:/usr/sbin:/sbin" TMPDIR="$WORK" WORK="$WORK" WHEEL="$WHEEL" \
  PYEXE="$PYEXE" EXTRAS="$EXTRAS" "${PASS[@]}" \
  "$PYEXE" "$WORK/bare.py" "$WORK" "$PYEXE" "$WORK/bin/bash" -c '
    bc_() { local a=${1/./} b=${2/./}; local d=$(( (10#$a - 10#$b) / 100000 ));
            echo "$((d / 10)).$((d % 10))"; }
    summary() { echo "$1=$2" >> "$WORK/summary"; }
    source "$WORK/payload.sh"'
echo "wheel_check: OK in $((SECONDS - t0)) s (of which the wheel $((t_built - t0)) s)"
if [ -n "${WHEEL_CHECK_SUMMARY:-}" ]; then
  echo "check_s=$((SECONDS - t0))" >> "$WORK/summary"
  cp "$WORK/summary" "$WHEEL_CHECK_SUMMARY"
fi
