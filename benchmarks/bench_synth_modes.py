"""bsp-synth: full mode (MP4 + APNG) against --poses-only, side by side, and what a preset
gives after conversion.

1. ``generate(preset, clips=K, workers=W)`` in both modes, run in turn (poses-only first,
   then full, ``--rounds`` times) so that both see the same machine load: wall and CPU
   seconds (this process and its workers), load average, and a byte comparison of the two
   data.csv files (they must be identical).
2. With ``--counts``: the clips per split and class of ``bsp-convert --no-media`` with the
   default options (L = 30) and with ``--benchmark`` (time-to-event windows, L = 16,
   offset 6), from the poses-only data.csv (the same bytes as the full mode's).

The machine may be shared: CPU seconds are the stable number, wall seconds what you wait.

    python benchmarks/bench_synth_modes.py --preset medium [--clips K] [--workers 2] [--counts]
"""
from __future__ import annotations

import argparse
import filecmp
import os
import shutil
import tempfile
import time
import warnings

import bsp_fast as bf
from bsp_fast.synth import generate
from bsp_fast.synth.config import PRESETS


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed(out: str, preset: str, clips, workers: int, poses_only: bool) -> dict:
    load0, c0, t0 = os.getloadavg()[0], _cpu(), time.perf_counter()
    s = generate(out, preset, clips=clips, workers=workers, poses_only=poses_only,
                 progress=False, force=True)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    size = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(out) for f in fs)
    return dict(wall=wall, cpu=cpu, clips=s["clips"], load=(load0 + os.getloadavg()[0]) / 2,
                mb=size / 1e6, rows=s["annotated_frames"])


def counts(dataset: str, tmp: str) -> None:
    for name, kw in (("default (L=30)", {}), ("--benchmark (L=16, offset 6)",
                                              dict(benchmark=True))):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a warning on a split is shown in the table
            r = bf.convert(dataset, os.path.join(tmp, "c.h5"), media=False, force=True, **kw)
        print(f"\n{name}: {sum(r['splits'][k]['clips'] for k in r['splits'])} clips, "
              f"{len(r['skipped'])} of {r['recordings']} recordings without a clip")
        print(f"  {'split':6s} {'not-crossing':>13s} {'crossing':>9s} {'recordings':>11s}")
        for k in ("train", "val", "test"):
            s = r["splits"][k]
            print(f"  {k:6s} {s['not-crossing']:13d} {s['crossing']:9d} {s['recordings']:11d}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", choices=sorted(PRESETS), default="medium",
                    help="preset to generate (default: %(default)s)")
    ap.add_argument("--clips", type=int, default=None, help="clips (default: the preset's)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default: "
                    "%(default)s)")
    ap.add_argument("--rounds", type=int, default=1, help="poses-only/full pairs (default: "
                    "%(default)s)")
    ap.add_argument("--skip-full", action="store_true", help="poses-only mode only")
    ap.add_argument("--counts", action="store_true", help="clip counts after conversion")
    args = ap.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix="bench_synth_modes-")
    try:
        po, fu = os.path.join(tmp, "poses"), os.path.join(tmp, "full")
        print(f"preset {args.preset}, clips {args.clips or PRESETS[args.preset]['number_of_clips']}"
              f", workers {args.workers}, {os.cpu_count()} cores")
        print(f"{'mode':10s} {'wall s':>8s} {'CPU s':>8s} {'CPU s/clip':>11s} {'load':>5s} "
              f"{'MB':>8s}")
        for _ in range(args.rounds):
            modes = [("poses-only", po, True)] + ([] if args.skip_full else [("full", fu, False)])
            for name, out, flag in modes:
                r = timed(out, args.preset, args.clips, args.workers, flag)
                print(f"{name:10s} {r['wall']:8.1f} {r['cpu']:8.1f} {r['cpu'] / r['clips']:11.2f} "
                      f"{r['load']:5.1f} {r['mb']:8.1f}", flush=True)
            if not args.skip_full:
                same = filecmp.cmp(os.path.join(po, "data.csv"), os.path.join(fu, "data.csv"),
                                   shallow=False)
                print(f"data.csv byte-identical: {same}")
                if not same:
                    return 1
        if args.counts:
            counts(po, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
