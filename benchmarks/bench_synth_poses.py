"""bsp-synth --poses-only against writing its own table; bsp-convert of the result against
``wc -l`` and ``read_csv`` of the same file (issue 59: "data in a minute").

One run, same files, each step timed in turn (the machine may be shared: the load
average is printed with every number, and the ratios are what to compare):

1. ``generate(PRESET, poses_only=True, workers=W)`` in this process (its workers are
   child processes): wall and CPU seconds.
2. The same table written again by ``bsp_fast.write_csv`` (all 24 columns, read back with
   ``read_csv`` first, default threads) into another file, checked byte-identical to the
   generated ``data.csv``. Generation / write_csv is the issue's "speed of its output".
3. With ``--convert``: ``wc -l data.csv``, ``bsp_fast.read_csv`` of the pose columns
   (in-process, default threads) and ``bsp-convert DIR OUT --no-media`` (a child
   process, like a user runs it), ``--repeat`` rounds in turn; the medians and the
   conversion's ratio to each.

    python3 benchmarks/bench_synth_poses.py [--preset full] [--workers 2] [--clips N]
        [--convert] [--repeat 3] [--dir DIR]
"""
from __future__ import annotations

import argparse
import filecmp
import hashlib
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# sha256 of the whole presets' data.csv as 4fba854 (which rendered whole frames) wrote them.
REFERENCE = Path(__file__).resolve().parents[1] / "tests" / "python" / "data" / "synth_reference.json"

POSE_COLUMNS = ["id", "frame.idx", "frame.pedestrian.pose.world",
                "frame.pedestrian.pose.component", "frame.pedestrian.pose.relative",
                "frame.pedestrian.pose.camera"]


def load() -> str:
    return f"{os.getloadavg()[0]:.2f}"


def cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed(fn):
    """(wall seconds, CPU seconds of this process and its waited-for children, result)."""
    w0, c0 = time.perf_counter(), cpu_seconds()
    out = fn()
    return time.perf_counter() - w0, cpu_seconds() - c0, out


def generation(root: Path, args) -> dict:
    """Steps 1 and 2: the dataset, then its table written again."""
    from bsp_fast import csvio
    from bsp_fast.synth import generate

    ds = root / "ds"
    before = load()
    wall, cpu, summary = timed(lambda: generate(
        ds, args.preset, clips=args.clips, workers=args.workers, poses_only=True, force=True,
        progress=False))
    table = csvio.read_csv(ds / "data.csv")
    again = root / "again.csv"
    before_w = load()
    w_wall, w_cpu, _ = timed(lambda: csvio.write_csv(again, table))
    same = filecmp.cmp(ds / "data.csv", again, shallow=False)
    ref = json.loads(REFERENCE.read_text()).get("whole_presets", {}).get(args.preset)
    if args.clips is None and ref:  # the whole preset, default seed
        sha = hashlib.sha256()
        with open(ds / "data.csv", "rb") as fh:
            for block in iter(lambda: fh.read(1 << 24), b""):
                sha.update(block)
        same_as_ref = sha.hexdigest() == ref["sha256"]
    else:
        same_as_ref = None
    rows = len(table["id"])
    del table
    again.unlink()
    return dict(ds=ds, rows=rows, clips=summary["clips"], wall=wall, cpu=cpu, load=before,
                write_wall=w_wall, write_cpu=w_cpu, write_load=before_w, identical=same,
                same_as_4fba854=same_as_ref,
                bytes=os.path.getsize(ds / "data.csv"))


def convert_child(ds: Path, out: Path) -> None:
    subprocess.run([sys.executable, "-c", "import sys; from bsp_fast.conversion import main; "
                    "sys.exit(main(sys.argv[1:]))", str(ds), str(out), "--force", "--quiet",
                    "--no-media"], check=True)


def conversion(ds: Path, out: Path, repeat: int) -> dict:
    """Step 3: wc -l, read_csv and bsp-convert in turn, `repeat` rounds."""
    import bsp_fast as bf

    csv = ds / "data.csv"
    runs: dict = {"wc -l": [], "read_csv": [], "bsp-convert": []}
    loads = []
    for _ in range(repeat):
        loads.append(load())
        runs["wc -l"].append(timed(lambda: subprocess.run(
            ["wc", "-l", str(csv)], check=True, capture_output=True))[0])
        runs["read_csv"].append(timed(lambda: bf.read_csv(csv, columns=POSE_COLUMNS))[0])
        runs["bsp-convert"].append(timed(lambda: convert_child(ds, out))[0])
    return dict(runs=runs, loads=loads)


def report(gen: dict, conv: dict | None, args) -> None:
    print(f"bsp-synth {args.preset} --poses-only, {gen['clips']} clips, {gen['rows']:,} rows, "
          f"{gen['bytes'] / 1e9:.2f} GB data.csv, {args.workers} workers, "
          f"{os.cpu_count()} cores:\n")
    print("| step | wall s | CPU s | load before |")
    print("|---|---:|---:|---:|")
    print(f"| generate (poses only) | {gen['wall']:.2f} | {gen['cpu']:.2f} | {gen['load']} |")
    print(f"| write_csv of its table | {gen['write_wall']:.2f} | {gen['write_cpu']:.2f} | "
          f"{gen['write_load']} |")
    print(f"\ngeneration / write_csv: {gen['wall'] / gen['write_wall']:.2f}x (wall); "
          f"write_csv's file byte-identical to data.csv: {gen['identical']}")
    if gen["same_as_4fba854"] is not None:
        print(f"data.csv sha256 equal to 4fba854's (which rendered every frame): "
              f"{gen['same_as_4fba854']}")
    if conv is None:
        return
    med = {k: statistics.median(v) for k, v in conv["runs"].items()}
    print(f"\nconversion of that data.csv ({len(conv['loads'])} rounds in turn, loads "
          f"{', '.join(conv['loads'])}):\n")
    print("| step | wall s (each round) | median | bsp-convert / this |")
    print("|---|---|---:|---:|")
    for k, v in conv["runs"].items():
        print(f"| {k} | {' '.join(f'{x:.2f}' for x in v)} | {med[k]:.2f} | "
              f"{med['bsp-convert'] / med[k]:.1f}x |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="full", help="bsp-synth preset (default: %(default)s)")
    ap.add_argument("--clips", type=int, default=None, help="clips (default: the preset's)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default: 2)")
    ap.add_argument("--convert", action="store_true", help="also time the conversion")
    ap.add_argument("--repeat", type=int, default=3, help="conversion rounds (default: 3)")
    ap.add_argument("--dir", default=None, help="work directory (default: a temporary one)")
    args = ap.parse_args(argv)
    root = Path(tempfile.mkdtemp(prefix="bench_synth_poses-", dir=args.dir))
    try:
        gen = generation(root, args)
        conv = conversion(gen["ds"], root / "out.h5", args.repeat) if args.convert else None
        report(gen, conv, args)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
