"""``bsp-reproduce TABLE --seeds N``: every row of a table trained with N training seeds
(weights, batch order, noise draws; with ``--split-seeds`` also the recording split), the
seeds run as parallel processes of one torch thread each, finished runs reused; the
table's budget rule checked; the learning curves of the table drawn. The statistics over
seeds and recordings are :mod:`bsp_fast.training.evidence`'s. See docs/reproduce.md.

Runs go to ``OUT/TABLE-BUDGET/ROW/seed-S/`` (ordinary ``bsp-train`` run directories), their
configs to ``OUT/TABLE-BUDGET/configs/ROW-seed-S.yaml``.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from . import config as C
from ..atomic import write_text
from ..defaults import SEED
from .breakdown import FILE as BREAKDOWN
from .curves import save_figure
from .table_files import (BUDGETS, RULE_KEYS, check_budget_rule, load_table, prepare_row_data,
                          row_options, wanted_rows)
from .noisy_boxes import noisy_box_metrics
from .runs import RunError, read_run, resumable

__all__ = ["RULE_KEYS", "check_budget_rule", "seed_list", "reproduce_seeds", "add_options",
           "learning_curves"]

#: options that make a table's budget rule: every row of a budget shares them, except a
#: row's ``batch_size`` when the row says why (``own_batch_size``)
def seed_list(n: int, base: int = SEED) -> list:
    """The training seeds of ``--seeds n``: ``base, base + 1, ...`` (the first is a
    single-seed run's)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"seeds must be an integer >= 1, got {n!r}")
    return [base + k for k in range(n)]


def add_options(p) -> None:
    """``--seeds``, ``--split-seeds`` and ``--jobs`` of ``bsp-reproduce``."""
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="train every row with N training seeds (weights, batch order, noise "
                        "draws): cells become mean ± std over seeds with a 95%% interval over "
                        "test recordings, findings are marked by a paired bootstrap "
                        "(default: 1, the single-run table)")
    p.add_argument("--split-seeds", action="store_true",
                   help="with --seeds: set the converter's split seed to the seed too (needs "
                        "a dataset directory; it shuffles the clips inside each split, the "
                        "recordings of each split stay the same; default: fixed)")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="with --seeds: runs trained at once, one process and one torch "
                        "thread each (default: the number of cores)")


def _plan(tab, data, budget, base: Path, wanted, seeds, split_seeds, overrides, threads):
    plan = []
    for row in tab["rows"]:
        if row["name"] not in wanted or row.get("initial_of"):
            continue
        for seed in seeds:
            run_dir = base / row["name"] / f"seed-{seed}"
            extra = dict(overrides or {}, seed=seed)
            if split_seeds:
                extra["split_seed"] = seed
            if threads:
                extra["threads"] = threads
            opts = row_options(tab, row, budget, data, run_dir, extra)
            C.validate(C.defaults() | opts)
            opts = prepare_row_data(tab, row, opts)
            plan.append((row, seed, run_dir, opts))
    return plan


def _convert_once(plan) -> None:
    """Converts each distinct dataset conversion before the parallel runs start (two
    processes must not write the same cache file)."""
    from .train import make_datamodule, prepare_data

    done = set()
    for _, _, _, opts in plan:
        cfg = C.defaults() | opts
        key = (cfg["data"], cfg["split_seed"], cfg["clip_length"], cfg["benchmark"])
        if key not in done:
            prepare_data(make_datamodule(cfg), stages=())
            done.add(key)


def _command(cfg_path, quiet: bool, stopped=None) -> list:
    """``python -m bsp_fast train --config CFG`` of this very package (a worker process
    that imports nothing from its parent: no forked torch or HDF5 state), or ``--resume
    RUN`` of an interrupted run."""
    what = ["--resume", str(stopped)] if stopped is not None else \
        ["--config", str(cfg_path), "--force"]
    return [sys.executable, "-m", "bsp_fast", "train", *what] + (["--quiet"] if quiet else [])


def _env() -> dict:
    import bsp_fast

    env = dict(os.environ)
    root = str(Path(bsp_fast.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in
                                                  env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _run(todo, jobs: int, quiet: bool, log) -> None:
    """Trains ``todo`` (``(name, config path)``) in up to ``jobs`` processes at once."""
    if jobs <= 1:  # in this process, one run after the other
        from .train import train

        for name, cfg_path, stopped in todo:
            t0 = time.perf_counter()
            if stopped is not None:  # interrupted or killed: continue, not restart
                log(f"[{name}] continuing the interrupted run {stopped}")
                train(resume=str(stopped), quiet=quiet)
            else:
                train(config=str(cfg_path), force=True, quiet=quiet)
            log(f"[{name}] done in {time.perf_counter() - t0:.0f} s")
        return
    import subprocess
    import tempfile

    pending, running = list(todo), []
    env = _env()
    try:
        while pending or running:
            while pending and len(running) < jobs:
                name, cfg_path, stopped = pending.pop(0)
                err = tempfile.TemporaryFile(mode="w+")
                proc = subprocess.Popen(_command(cfg_path, quiet, stopped), env=env, stderr=err,
                                        stdout=subprocess.DEVNULL if quiet else None)
                running.append((name, proc, err, time.perf_counter()))
            time.sleep(0.2)
            for item in list(running):
                name, proc, err, t0 = item
                if proc.poll() is None:
                    continue
                running.remove(item)
                err.seek(0)
                tail = err.read()[-2000:]
                err.close()
                if proc.returncode != 0:
                    raise RunError(f"{name}: bsp-train exited with {proc.returncode}:\n{tail}")
                log(f"[{name}] done in {time.perf_counter() - t0:.0f} s")
    finally:
        for _, proc, err, _ in running:  # only the processes started here
            proc.terminate()
            proc.wait()
            err.close()


def _seed_result(run_dir: Path) -> dict:
    run = read_run(run_dir)
    m = run["metrics"]
    return {"metrics": m.get("test", {}), "initial": (m.get("initial") or {}).get("test", {}),
            "baseline": (m.get("initial") or {}).get("baseline"), "epochs": m.get("epochs"),
            "best_epoch": m.get("best_epoch"), "seconds": m.get("seconds", {}),
            "precision": m.get("precision"), "run": str(run_dir),
            "per_recording": str(run_dir / BREAKDOWN) if (run_dir / BREAKDOWN).is_file()
            else None, "noise": run["config"].get("noise"), "mjp": run["config"].get("mjp")}


def reproduce_seeds(table, data, budget: str = "quick", out="runs", *, seeds: int = 2,
                    split_seeds: bool = False, jobs: int | None = None, rows=None,
                    overrides=None, force: bool = False, quiet: bool = True,
                    dry_run: bool = False, log=print) -> dict:
    """Trains the rows of ``table`` with ``seeds`` training seeds each (``jobs`` processes
    at once, one torch thread each when ``jobs`` > 1) and returns ``{"table", "budget",
    "dir", "seeds", "split_seeds", "results": {row: {"seeds": {seed: {...}}, "noise",
    "mjp", "source"}}}``; the statistics are :func:`evidence.summarise`'s."""
    tab = table if isinstance(table, dict) else load_table(table)
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {list(BUDGETS)}, got {budget!r}")
    seed_values = seed_list(seeds)
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an integer >= 1, got {jobs!r}")
    if split_seeds and Path(data).suffix in (".h5", ".hdf5"):
        raise ValueError("--split-seeds needs a dataset directory: an HDF5 file holds one "
                         "split")
    wanted = wanted_rows(tab, rows)
    base = Path(out) / f"{tab['table']}-{budget}"
    plan = _plan(tab, data, budget, base, wanted, seed_values, split_seeds, overrides,
                 1 if jobs > 1 else None)
    todo = []
    for row, seed, run_dir, opts in plan:
        import yaml

        cfg_path = base / "configs" / f"{row['name']}-seed-{seed}.yaml"
        cfg_path.parent.mkdir(parents=True, exist_ok=True)
        write_text(cfg_path, "# bsp-reproduce: one row and seed, usable as bsp-train "
                   "--config\n" + yaml.safe_dump(opts, sort_keys=False))
        if dry_run:
            log(f"bsp-train --config {cfg_path}")
        elif (run_dir / "metrics.json").is_file() and not force:
            log(f"[{row['name']} seed {seed}] reusing {run_dir} (--force to train again)")
        else:  # an interrupted run of an earlier call continues (unless --force)
            todo.append((f"{row['name']} seed {seed}", cfg_path,
                         None if force else resumable(run_dir)))
    if dry_run:
        return {"table": tab["table"], "budget": budget, "dir": str(base), "results": {}}
    if todo:
        _convert_once(plan)
        log(f"training {len(todo)} run(s), {min(jobs, len(todo))} at a time")
        _run(todo, jobs, quiet, log)
    results = {}
    for row, seed, run_dir, _ in plan:
        r = results.setdefault(row["name"], {"seeds": {}, "source": "test"})
        r["seeds"][str(seed)] = one = _seed_result(run_dir)
        if not row.get("initial_of"):  # pose estimation: the same run on noisy boxes
            one["metrics"].update(noisy_box_metrics(tab, run_dir, force, quiet, log))
        r["noise"], r["mjp"] = one["noise"], one["mjp"]
    for row in tab["rows"]:  # rows read from another row's trivial baseline
        src = row.get("initial_of")
        if row["name"] in wanted and src and src in results:
            results[row["name"]] = dict(results[src], source="initial", run_of=src)
    return {"table": tab["table"], "budget": budget, "dir": str(base), "seeds": seed_values,
            "split_seeds": bool(split_seeds), "results": results}


# ---------------------------------------------------------------------- learning curves
def _val_series(run_dir: Path, metric: str) -> dict:
    """``{optimiser updates: val metric}`` of one run, from its CSV logs."""
    import csv

    out = {}
    for f in sorted(Path(run_dir).glob("logs/version_*/metrics.csv")):
        with open(f, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                text, step = row.get(f"val/{metric}"), row.get("step")
                if text not in (None, "") and step not in (None, ""):
                    # Lightning logs epoch-end values at the index of the last update
                    out[int(float(step)) + 1] = float(text)
    return out


def learning_curves(tab: dict, res: dict, path=None):
    """``curves.png`` of a table: the validation main metric (the table's first) against
    optimiser updates for every trained row, the mean over seeds and a band of ± one
    standard deviation. Returns the path, or None when nothing was logged."""
    import numpy as np

    metric = next(iter(tab["metrics"]))
    series = {}
    for name, r in res["results"].items():
        if r.get("source") != "test":
            continue
        runs = [_val_series(Path(s["run"]), metric) for s in r["seeds"].values()]
        steps = sorted({k for run in runs for k in run})
        if steps:
            vals = [[run[k] for run in runs if k in run] for k in steps]
            series[name] = (np.array(steps), np.array([np.mean(v) for v in vals]),
                            np.array([np.std(v) for v in vals]))
    if not series:
        return None
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, (x, mean, std) in series.items():
        line, = ax.plot(x, mean, marker=".", label=name)
        ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    spec = tab["metrics"][metric]
    ax.set_xlabel("optimiser updates")
    ax.set_ylabel(f"val {spec['label']}")
    ax.grid(alpha=0.3)
    ax.legend(title=f"mean ± std over {len(res.get('seeds') or [1])} seed(s)")
    ax.set_title(f"{tab['table']} — budget {res['budget']}")
    fig.tight_layout()
    out = Path(path) if path is not None else Path(res["dir"]) / "curves.png"
    return save_figure(fig, out)
