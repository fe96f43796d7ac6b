"""How long each command takes to answer: ``--help``, argument and input errors, and
``bsp-eval``/``bsp-predict`` on a small run (a sample dataset, a one-epoch lifting LSTM and
classification LSTM). Wall seconds of the whole process, the median of ``--repeat`` runs
each, side by side with ``python -c pass`` and ``import torch`` (what no command can beat
once it needs PyTorch) in the same run.

    python3 benchmarks/bench_cli_latency.py [--repeat 5] [--out results.json] [--only help]

Run it on a quiet machine: the numbers are wall times. Targets (the front-door issue):
``--help`` and argument errors at most 1 s, bsp-eval and bsp-predict on a small run at
most 4 s.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

HELP = ["bsp-synth", "bsp-convert", "bsp-train", "bsp-eval", "bsp-predict", "bsp-reproduce",
        "bsp-preview", "bsp-check", "bsp-cache", "bsp-interop"]
ERRORS = [["bsp-train", "lifitng", "lstm"],
          ["bsp-train", "lifting", "lstm", "--data", "/nope.h5"],
          ["bsp-train", "lifting", "lstm", "--data", "s.h5", "--out", "s.h5"],
          ["bsp-eval", "/nope"],
          ["bsp-predict", "/nope", "--out", "p.h5"],
          ["bsp-reproduce", "clasification", "--data", "s.h5"],
          ["bsp-convert", "/nope", "o.h5"],
          ["bsp-interop", "export", "coco", "/nope.h5", "o.json"],
          ["bsp-synth", "out", "--config", "/nope.yaml"],
          ["bsp-preview", "clips", "/nope.h5", "--out", "x.png"],
          ["bsp-check", "/nope"],
          ["bsp-cache", "where", "/nope"]]
SCORING = [["bsp-eval", "lifting", "--quiet"], ["bsp-eval", "classification", "--quiet"],
           ["bsp-predict", "lifting", "--out", "p.h5", "--force", "--quiet"],
           ["bsp-predict", "classification", "--out", "c.h5", "--force", "--quiet"]]
BASELINES = [[sys.executable, "-c", "pass"], [sys.executable, "-c", "import torch"]]


def _time(argv, cwd) -> tuple:
    t0 = time.perf_counter()
    r = subprocess.run(argv, cwd=cwd, capture_output=True, text=True)
    return time.perf_counter() - t0, r.returncode


def _median(argv, cwd, repeat: int) -> dict:
    times, codes = zip(*(_time(argv, cwd) for _ in range(repeat)))
    return {"command": " ".join(a if a != sys.executable else "python" for a in argv),
            "median_s": statistics.median(times), "min_s": min(times), "exit": codes[0]}


def _small_runs(cwd: str) -> None:
    """A sample dataset converted, and one-epoch runs ``lifting`` and ``classification``."""
    steps = [["bsp-synth", "d", "--preset", "sample", "--poses-only", "--quiet"],
             ["bsp-convert", "d", "s.h5", "--quiet"],
             ["bsp-train", "lifting", "lstm", "--data", "s.h5", "--epochs", "1",
              "--batch-size", "8", "--precision", "32", "--out", "lifting", "--quiet"],
             ["bsp-train", "classification", "lstm", "--data", "s.h5", "--epochs", "1",
              "--batch-size", "8", "--precision", "32", "--out", "classification",
              "--quiet"]]
    for argv in steps:
        subprocess.run(argv, cwd=cwd, check=True, capture_output=True)


def _machine() -> dict:
    """The CPU model, its bf16-relevant flags, cores and load (/proc/cpuinfo)."""
    info = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    flags = info.get("flags", "").split()
    keep = [f for f in ("avx2", "avx512f", "avx512_bf16", "amx_bf16") if f in flags]
    return {"cpu": info.get("model name", platform.processor()), "flags": keep,
            "cores": os.cpu_count(), "load_1min": os.getloadavg()[0]}


def run(repeat: int, only: str | None = None) -> dict:
    groups = {"baseline": BASELINES, "help": [[c, "--help"] for c in HELP],
              "error": ERRORS, "scoring": SCORING}
    rows = {}
    with tempfile.TemporaryDirectory() as cwd:
        if only in (None, "scoring", "error"):
            _small_runs(cwd)
        for name, commands in groups.items():
            if only is not None and name not in (only, "baseline"):
                continue
            rows[name] = [_median(argv, cwd, repeat) for argv in commands]
    return {"repeat": repeat, "machine": _machine(), "rows": rows}


def table(result: dict) -> str:
    limits = {"help": 1.0, "error": 1.0, "scoring": 4.0, "baseline": None}
    lines = ["| group | command | median s | min s | exit | target |",
             "|---|---|---|---|---|---|"]
    for group, rows in result["rows"].items():
        for r in rows:
            limit = limits[group]
            ok = "" if limit is None else ("ok" if r["median_s"] <= limit else f"> {limit:g} s")
            lines.append(f"| {group} | `{r['command']}` | {r['median_s']:.2f} | "
                         f"{r['min_s']:.2f} | {r['exit']} | {ok} |")
    m = result["machine"]
    lines.append(f"\nmedian of {result['repeat']}; {m['cpu']}, {m['cores']} cores, flags "
                 f"{' '.join(m['flags'])}, load {m['load_1min']:.2f} at the end")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--only", choices=("help", "error", "scoring"))
    p.add_argument("--out", help="also write the results as JSON here")
    a = p.parse_args(argv)
    result = run(a.repeat, a.only)
    result["machine"]["load_1min"] = os.getloadavg()[0]
    print(table(result))
    if a.out:
        with open(a.out, "w") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
