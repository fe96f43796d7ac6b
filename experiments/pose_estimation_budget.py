#!/usr/bin/env python3
"""The training budget of ``pose_estimation/pose_temporal`` fixed on validation curves, and
the ablation table of issue #38 written with it (docs/findings.md, "Pose estimation").

Stage 1, the curves (no test number is made: every run is trained and "tested" on a file
whose test split is a link to its val split, ``OUT/data/``):

    python experiments/pose_estimation_budget.py curves --data data/medium --out runs/pose_budget

trains the full model (temporal context, soft-argmax, box jitter as the evaluation's
noise, flips/zoom/rotation) for each ``--crop-sizes`` x ``--widths`` x ``--seeds`` on one
thread each (``--jobs`` at a time) in chunks of ``--chunk-epochs`` epochs, each chunk a
``--resume`` of the run, until its validation curve has a plateau (rule below) or its
process CPU time passes ``--cpu-minutes``. Then it fixes the budget:

* a configuration's curve is the mean over its seeds of validation PCK@0.05 at each
  epoch's update count (same data and batch size: the same counts);
* **plateau**: the first epoch whose best-so-far is within ``--tolerance`` of the curve's
  best, followed by at least ``--patience`` more epochs (none gaining more than
  ``--tolerance`` on it); no such epoch: no plateau within the CPU cap;
* the budget (updates) is the latest plateau over the configurations (each row of the
  ablation table trains as long), or their cap where a curve has none, and at most what
  the costliest configuration can train in ``--cpu-minutes`` (its CPU seconds per update:
  training, validation and data loading of its runs);
* the crop size and width of the table's ``full`` row: the best mean validation PCK@0.05
  at the budget's last epoch (validation data only).

Writes ``budget.json``, ``budget.md``, ``budget_curves.png`` and the ablation table
``ablation_pose_temporal.yaml`` (rows: full; temporal off; DARK on the same training;
heatmap loss + DARK; box jitter off; image augmentation off; the other crop sizes and
widths; the old pose_cnn as the main table trains it, at the same budget; the average
skeleton of its clean training crops) into ``--out``. Commit the table under experiments/
before running it (bsp-reproduce records its hash):

    bsp-reproduce --table runs/pose_budget/ablation_pose_temporal.yaml --data data/medium \\
        --seeds 3 --jobs 2

``--rule cpu`` chooses the configuration by its validation PCK@0.05 at equal CPU instead
(the least CPU every run reached), and the budget is that configuration's own plateau or
the updates it affords in ``--cpu-minutes``: the main table's pose_temporal row, where the
crop size is a cost as much as a setting. ``--no-train`` fixes the budget from the runs as
they are. ``table`` rewrites the table from an existing ``budget.json``. ``--smoke``: one epoch of
two batches per chunk, two chunks, one seed, width 4: the plumbing only.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

MODEL = "pose_temporal"
METRIC = "val/pck_0.05"
TABLE = "ablation_pose_temporal"
#: the evaluation's detector-like box noise (experiments/pose_estimation.yaml), trained on
JITTER = {"box_jitter_scale": 0.1, "box_jitter_shift": 0.05}


# ---------------------------------------------------------------------- curves and rule
def plateau(updates, values, tolerance: float, patience: int) -> dict:
    """The module docstring's plateau rule on one curve: ``{"reached", "index", "updates",
    "value", "best"}`` (``index``/``updates``/``value``: the plateau's epoch, or the last
    epoch when there is none)."""
    u, v = np.asarray(updates, float), np.asarray(values, float)
    if not len(v):
        return {"reached": False, "index": None, "updates": None, "value": None, "best": None}
    best = float(v.max())
    first = int(np.argmax(np.maximum.accumulate(v) >= best - tolerance))
    reached = len(v) - 1 - first >= patience
    at = first if reached else len(v) - 1
    return {"reached": bool(reached), "index": at, "updates": float(u[at]),
            "value": float(v[at]), "best": best}


def run_series(run_dir) -> dict:
    """``{"updates", "cpu_s", "value"}`` per validated epoch of one run over all its
    ``logs/version_*`` (one per resume). A resumed run's ``cost/cpu_s`` restarts at 0, so
    each version is offset by the CPU seconds of the versions before it."""
    files = sorted(Path(run_dir).glob("logs/version_*/metrics.csv"),
                   key=lambda p: int(p.parent.name.split("_")[-1]))
    rows, offset = {}, 0.0
    for f in files:
        last = 0.0
        with open(f, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                if not row.get("epoch") or not row.get("cost/cpu_s"):
                    continue
                cpu = float(row["cost/cpu_s"])
                last = max(last, cpu)
                rows.setdefault(int(float(row["epoch"])), {}).update(
                    updates=float(row["cost/updates"]), cpu_s=offset + cpu)
            fh.seek(0)
            for row in csv.DictReader(fh):
                if row.get("epoch") and row.get(METRIC):
                    rows.setdefault(int(float(row["epoch"])), {})["value"] = float(row[METRIC])
        offset += last
    done = [e for e in sorted(rows) if {"updates", "cpu_s", "value"} <= set(rows[e])]
    return {k: np.array([rows[e][k] for e in done]) for k in ("updates", "cpu_s", "value")}


def mean_curve(series: list) -> tuple:
    """``(updates, mean value, std)`` over seeds at the update counts every seed logged."""
    series = [s for s in series if len(s["value"])]
    if not series:
        return np.array([]), np.array([]), np.array([])
    common = sorted(set.intersection(*(set(s["updates"].tolist()) for s in series)))
    vals = np.array([[s["value"][list(s["updates"]).index(u)] for u in common] for s in series])
    std = vals.std(0, ddof=1) if len(series) > 1 else np.zeros(len(common))
    return np.array(common), vals.mean(0), std


def at_equal_cpu(configs: dict) -> dict:
    """``{"cpu_s", "values": {name: mean val value}}``: each configuration's mean curve at
    the CPU every one of its seeds reached in every configuration (the smallest of their
    last CPU seconds): the value of its last epoch within that CPU, per seed, averaged."""
    lasts = [x["cpu_s"][-1] for c in configs.values() for x in c["series"] if len(x["cpu_s"])]
    if not lasts:
        return {"cpu_s": None, "values": {}}
    cpu = float(min(lasts))
    values = {}
    for name, c in configs.items():
        per = [x["value"][np.flatnonzero(x["cpu_s"] <= cpu)[-1]] for x in c["series"]
               if len(x["cpu_s"]) and x["cpu_s"][0] <= cpu]
        values[name] = float(np.mean(per)) if per else None
    return {"cpu_s": cpu, "values": values}


def fix_budget(configs: dict, cpu_cap_s: float, tolerance: float, patience: int,
               rule: str = "updates") -> dict:
    """The budget from ``{name: {"crop_size", "width", "series": [per seed]}}`` (module
    docstring); JSON-able. ``rule="cpu"``: the configuration is chosen by its validation
    value at equal CPU (:func:`at_equal_cpu`), and the budget is that configuration's own
    plateau, or the updates it affords in the cap (the others are compared, not trained
    as long)."""
    if rule not in ("updates", "cpu"):
        raise ValueError(f"rule must be 'updates' or 'cpu', got {rule!r}")
    out = {"configs": {}, "tolerance": tolerance, "patience": patience,
           "cpu_minutes_cap": cpu_cap_s / 60, "rule": rule,
           "equal_cpu": at_equal_cpu(configs)}
    wants, costs = [], []
    for name, c in configs.items():
        u, m, s = mean_curve(c["series"])
        p = plateau(u, m, tolerance, patience)
        used = [(x["cpu_s"][-1], x["updates"][-1]) for x in c["series"] if len(x["updates"])]
        per_update = float(np.median([cpu / n for cpu, n in used])) if used else float("nan")
        out["configs"][name] = {"crop_size": c["crop_size"], "width": c["width"],
                                "updates": u.tolist(), "mean": m.tolist(), "std": s.tolist(),
                                "plateau": p, "cpu_s_per_update": per_update}
        if p["updates"] is not None:
            wants.append(p["updates"])
            costs.append(per_update)
    if not wants:
        raise ValueError("no run logged a validated epoch: nothing to fix a budget on")
    if rule == "cpu":
        eq = {n: v for n, v in out["equal_cpu"]["values"].items() if v is not None}
        pick = out["configs"][max(eq, key=eq.get)]
        wants, costs = [pick["plateau"]["updates"]], [pick["cpu_s_per_update"]]
    want, affordable = max(wants), math.floor(cpu_cap_s / max(costs))
    updates = int(min(want, affordable))
    per_epoch = min(v["updates"][0] for v in out["configs"].values() if v["updates"])
    epochs = max(1, math.ceil(updates / per_epoch))
    at = {}
    for name, v in out["configs"].items():  # validation PCK at (or before) the budget
        ok = [i for i, x in enumerate(v["updates"]) if x <= updates]
        at[name] = v["mean"][ok[-1]] if ok else None
    best = max((n for n in at if at[n] is not None), key=at.get) if rule == "updates" else \
        max(eq, key=eq.get)
    out.update(updates=updates, epochs=epochs, updates_per_epoch=per_epoch,
               limited_by_cpu=affordable < want,
               all_plateaued=all(v["plateau"]["reached"] for v in out["configs"].values()),
               val_at_budget=at, chosen=best, crop_size=out["configs"][best]["crop_size"],
               width=out["configs"][best]["width"])
    return out


# ---------------------------------------------------------------------- data and runs
def val_as_test(h5, path) -> Path:
    """A file whose ``train``/``val`` link to ``h5``'s and whose ``test`` links to its
    ``val``: bsp-train's closing test then scores validation clips only."""
    import h5py

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with h5py.File(h5, "r") as f, h5py.File(tmp, "w") as g:
        for key, value in f.attrs.items():
            g.attrs.create(key, value, dtype=f.attrs.get_id(key).dtype)
        for split, target in (("train", "/train"), ("val", "/val"), ("test", "/val")):
            g[split] = h5py.ExternalLink(str(Path(h5).resolve()), target)
    from bsp_fast.atomic import publish

    publish(tmp, path, force=True)
    return path


def converted(data, crop_size: int, common: dict) -> Path:
    """The converted file bsp-train would use for ``data`` at ``crop_size`` (converted and
    cached on first use); an HDF5 ``data`` is used as it is and must have that crop size."""
    import h5py

    from bsp_fast.training import config as C
    from bsp_fast.training.setup import make_datamodule, prepare_data

    if Path(data).suffix in (".h5", ".hdf5"):
        with h5py.File(data, "r") as f:
            have = int(f["train/frames/rgb"].shape[1])
        if have != crop_size:
            raise ValueError(f"{data}: crops of {have} px, not {crop_size}; give a dataset "
                             "directory to convert at several crop sizes")
        return Path(data)
    cfg = C.validate({**C.defaults(), **common, "data": str(data), "crop_size": crop_size,
                      "quiet": True})
    dm = make_datamodule(cfg)
    prepare_data(dm, stages=())
    return Path(dm.h5_path)


def run_curve(job: dict) -> str:
    """Trains one (configuration, seed) in chunks of epochs until a plateau or the CPU cap
    (a finished or interrupted run is continued, never started again)."""
    import bsp_fast

    run, opts = Path(job["run_dir"]), dict(job["options"])
    chunk, cap, tol, pat = job["chunk"], job["cpu_cap_s"], job["tolerance"], job["patience"]
    epochs = chunk
    while True:
        series = run_series(run) if run.exists() else None
        if series is not None and len(series["value"]):
            done = len(series["value"])
            if series["cpu_s"][-1] >= cap or done >= job["max_epochs"] \
                    or plateau(series["updates"], series["value"], tol, pat)["reached"]:
                return str(run)
            epochs = done + chunk
        if (run / "checkpoints" / "last.ckpt").exists():
            bsp_fast.train(resume=run, epochs=epochs, quiet=True)
        else:
            bsp_fast.train(out=run, epochs=epochs, quiet=True, force=True, **opts)


def _pool_map(fn, jobs: list, n: int) -> list:
    """``pool.map`` over ``n`` processes where a SIGTERM sent to this process alone reaches
    the workers too: each gets SIGTERM (bsp-train's: the run is saved to be resumed), the
    jobs not started are dropped, and this process exits with 143 once they have ended."""
    import signal

    with ProcessPoolExecutor(n, mp_context=get_context("spawn")) as pool:
        def stop(signum, frame):
            for proc in list(pool._processes.values()):  # the running workers
                proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise SystemExit(128 + signum)

        old = signal.signal(signal.SIGTERM, stop)
        try:
            return list(pool.map(fn, jobs))
        finally:
            signal.signal(signal.SIGTERM, old)


def configurations(args) -> dict:
    return {f"crop{s}-w{w}": {"crop_size": s, "width": w}
            for s in args.crop_sizes for w in args.widths}


def train_options(args, h5: Path, crop_size: int, width: int, seed: int) -> dict:
    """The full model's bsp-train options (the table's ``full`` row) for one curve run."""
    opts = dict(task="pose_estimation", model=MODEL, data=str(h5), crop_size=crop_size,
                seed=seed, batch_size=args.batch_size, early_stop=0, threads=1,
                accelerator="cpu", precision="32" if args.smoke else args.precision,
                image_augment=True, hp={"width": width, **({"flip_test": True}
                                                           if args.flip_test else {})},
                **JITTER)
    if args.smoke:
        opts.update(limit_batches=2, image_rotation=15.0)
    return opts


def curves(args) -> int:
    out = Path(args.out)
    common = {"task": "pose_estimation", "model": MODEL}
    jobs = []
    for name, c in configurations(args).items():
        h5 = converted(args.data, c["crop_size"], common)
        linked = val_as_test(h5, out / "data" / f"crop{c['crop_size']}-val-as-test.h5")
        for seed in range(args.seeds):
            jobs.append(dict(run_dir=str(out / "runs" / name / f"seed-{seed}"),
                             options=train_options(args, linked, c["crop_size"], c["width"],
                                                   seed),
                             chunk=args.chunk_epochs, cpu_cap_s=args.cpu_minutes * 60,
                             tolerance=args.tolerance, patience=args.patience,
                             max_epochs=args.max_epochs))
    print(f"{len(jobs)} curve runs ({args.jobs} at a time, one thread each) -> {out}/runs",
          flush=True)
    if args.no_train:
        jobs = []
    if args.jobs > 1 and jobs:
        _pool_map(run_curve, jobs, args.jobs)
    else:
        for job in jobs:
            run_curve(job)
    configs = {name: dict(c, series=[run_series(out / "runs" / name / f"seed-{s}")
                                     for s in range(args.seeds)])
               for name, c in configurations(args).items()}
    budget = fix_budget(configs, args.cpu_minutes * 60, args.tolerance, args.patience,
                        args.rule)
    budget.update(batch_size=args.batch_size, seeds=args.seeds, smoke=bool(args.smoke),
                  crop_sizes=list(args.crop_sizes), widths=list(args.widths),
                  data=str(args.data))
    write_budget(out, budget)
    write_table(out, budget)
    return 0


# ---------------------------------------------------------------------- outputs
def write_budget(out: Path, b: dict) -> None:
    from bsp_fast.atomic import write_text

    write_text(out / "budget.json", json.dumps(b, indent=1) + "\n")
    lines = [f"# pose_temporal: the budget from validation curves{' (SMOKE)' if b['smoke'] else ''}",
             "", f"Data {b['data']}, batch {b['batch_size']}, {b['seeds']} seed(s) per "
             f"configuration, CPU cap {b['cpu_minutes_cap']:g} min per run, plateau: within "
             f"{b['tolerance']:g} of the best, then {b['patience']} epochs.", "",
             "| configuration | epochs | plateau at (updates) | val PCK@0.05 there | best | "
             "CPU s per update | val PCK@0.05 at the budget |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, c in b["configs"].items():
        p = c["plateau"]
        where = f"{p['updates']:.0f}" if p["reached"] else f"none (last: {p['updates']:.0f})"
        lines.append(f"| {name} | {len(c['updates'])} | {where} | {p['value']:.3f} | "
                     f"{p['best']:.3f} | {c['cpu_s_per_update']:.2f} | "
                     f"{_fmt(b['val_at_budget'][name])} |")
    eq = b.get("equal_cpu") or {}
    if eq.get("cpu_s") is not None:
        lines += ["", f"Validation PCK@0.05 at equal CPU ({eq['cpu_s'] / 60:.1f} CPU min, the "
                  "least any run reached): " + ", ".join(
                      f"{n} {_fmt(v)}" for n, v in eq["values"].items()) + "."]
    rule = b.get("rule", "updates")
    lines += ["", "Rule: " + ("every configuration trains the budget's updates; the full row "
                              "is the best at them." if rule == "updates" else
                              "the full row is the best at equal CPU; the budget is its own "
                              "plateau, or the updates it affords in the cap.")]
    cap = " (cut by the CPU cap)" if b["limited_by_cpu"] else ""
    lines += ["", f"**Budget: {b['updates']} updates{cap}, {b['epochs']} epochs of "
              f"{b['updates_per_epoch']:.0f}.** Every curve reached a plateau: "
              f"{'yes' if b['all_plateaued'] else 'NO (the budget is the cap, not a plateau)'}. "
              f"Full row: crop {b['crop_size']}, "
              f"width {b['width']}.", ""]
    write_text(out / "budget.md", "\n".join(lines))
    _figure(out / "budget_curves.png", b)


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def _figure(path: Path, b: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, c in b["configs"].items():
        u, m, s = (np.asarray(c[k]) for k in ("updates", "mean", "std"))
        ax.plot(u, m, marker=".", label=name)
        ax.fill_between(u, m - s, m + s, alpha=0.2)
    ax.axvline(b["updates"], color="k", ls="--", lw=1, label="budget")
    ax.set(xlabel="optimiser updates", ylabel="val PCK@0.05 (mean ± sd over seeds)",
           title="pose_temporal: validation curves")
    ax.legend(fontsize=8)
    fig.tight_layout()
    from bsp_fast.atomic import write_bytes
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    write_bytes(path, buf.getvalue())


def ablation_table(b: dict) -> dict:
    """The ablation table file (a dict for YAML) with budget ``b``."""
    S, W = b["crop_size"], b["width"]
    full = {"model": MODEL, "hp": {"width": W}, "image_augment": True, **JITTER}

    def row(name, label, **change):
        hp = dict(full["hp"], **change.pop("hp", {}))
        return {"name": name, "label": label, "options": {**full, **change, "hp": hp}}

    rows = [row("full", f"pose_temporal (crop {S}, width {W})"),
            row("no_temporal", "temporal context off", hp={"temporal": "none"}),
            row("dark", "DARK decoding (same training)", hp={"decode": "dark"}),
            row("heatmap_dark", "heatmap loss + DARK", hp={"loss": "heatmap", "decode": "dark"}),
            row("no_box_jitter", "no train-time box jitter", box_jitter_scale=0.0,
                box_jitter_shift=0.0),
            row("no_image_augment", "no flips/zoom/rotation", image_augment=False)]
    rows += [row(f"crop{s}", f"crop {s}", crop_size=s) for s in b["crop_sizes"] if s != S]
    rows += [row(f"width{w}", f"width {w}", hp={"width": w})
             for w in sorted({max(1, W // 2), 2 * W} | set(b["widths"])) if w != W]
    # the old model as the main table trains it (no augmentation, no jitter; its quick lr),
    # and the average skeleton of those clean training crops, the main table's baseline
    # (one fitted on flipped, jittered crops would be a weaker one)
    rows += [{"name": "pose_cnn", "label": "PoseCNN (old settings, same budget)",
              "options": {"model": "pose_cnn", "lr": 0.001}},
             {"name": "average_skeleton", "label": "average skeleton",
              "initial_of": "pose_cnn"}]
    q = {"epochs": b["epochs"], "max_steps": b["updates"], "batch_size": b["batch_size"],
         "accelerator": "cpu", "precision": "auto", "early_stop": 0, "threads": 1}

    def compare(metric, a, b_, text, margin=0.0):
        return {"kind": "compare", "metric": metric, "a": a, "b": b_, "relation": ">",
                "margin": margin, "text": text, "report_text": "not in the report"}

    return {
        "table": TABLE, "task": "pose_estimation",
        "title": "pose_temporal ablations (issue #38; test split, PCK in %)",
        "metrics": {"pck_0.05": {}, "pck_0.05_visible": {}, "pck_0.05_occluded": {},
                    "pck_0.05_hands": {}, "pck_0.05_feet": {}, "pckhn_0.1": {},
                    "pck_0.05_noisy": {}},
        "box_noise": {"scale": 0.1, "shift": 0.05},
        "budget_rule": f"every row trains exactly max_steps optimiser updates (fixed on "
                       f"validation curves by experiments/pose_estimation_budget.py: "
                       f"{b['updates']} updates{', the CPU cap' if b['limited_by_cpu'] else ''}) "
                       "at the budget's batch size without early stopping; the best "
                       "checkpoint by validation loss is tested",
        "common": {"task": "pose_estimation", "crop_size": S},
        "budgets": {"smoke": {"epochs": 1, "batch_size": 2, "limit_batches": 2,
                              "accelerator": "cpu", "precision": "32"}, "quick": q},
        "rows": rows,
        "findings": [
            compare("pck_0.05", "full", "no_temporal", "temporal context helps (PCK@0.05)"),
            compare("pck_0.05", "dark", "full", "DARK beats the soft-argmax on one training"),
            compare("pck_0.05", "full", "heatmap_dark",
                    "integral training beats heatmap regression + DARK"),
            compare("pck_0.05_noisy", "full", "no_box_jitter",
                    "box jitter in training helps on noisy boxes"),
            compare("pck_0.05", "full", "no_image_augment", "image augmentation helps"),
            compare("pck_0.05", "full", "average_skeleton",
                    "goal: more than 15 p.p. above the average skeleton", margin=0.15),
            {"kind": "at_least", "metric": "pck_0.05", "row": "full", "value": 0.85,
             "text": "goal: PCK@0.05 >= 85 %", "report_text": "our target"},
            {"kind": "at_least", "metric": "pck_0.05_noisy", "row": "full", "value": 0.75,
             "text": "goal: PCK@0.05 on noisy boxes >= 75 %", "report_text": "our target"}],
    }


def write_table(out: Path, b: dict) -> Path:
    import yaml

    from bsp_fast.atomic import write_text

    head = (f"# Written by experiments/pose_estimation_budget.py from {out / 'budget.json'}"
            f"{' (SMOKE: not a budget)' if b['smoke'] else ''}.\n# Commit it under "
            "experiments/ before running it: bsp-reproduce records its hash.\n")
    path = out / f"{TABLE}.yaml"
    write_text(path, head + yaml.safe_dump(ablation_table(b), sort_keys=False, width=100))
    print(f"budget: {b['updates']} updates ({b['epochs']} epochs); wrote {out / 'budget.md'}, "
          f"{path}\nnext: bsp-reproduce --table {path} --data {b['data']} --seeds 3 --jobs 2")
    return path


# ---------------------------------------------------------------------- command line
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="stage", required=True)
    c = sub.add_parser("curves", help="train the validation curves, fix the budget, write "
                                      "the ablation table")
    c.add_argument("--data", required=True, help="dataset directory with media (converted per "
                   "crop size, cached) or one converted HDF5 file")
    c.add_argument("--out", default="runs/pose_budget", help="output folder")
    c.add_argument("--crop-sizes", type=int, nargs="+", default=[64, 96, 128])
    c.add_argument("--widths", type=int, nargs="+", default=[16])
    c.add_argument("--seeds", type=int, default=2, help="seeds per configuration (2)")
    c.add_argument("--jobs", type=int, default=2, help="runs at a time, one thread each (2)")
    c.add_argument("--batch-size", type=int, default=4, help="clips per update (4)")
    c.add_argument("--cpu-minutes", type=float, default=60.0, help="CPU cap per run (60)")
    c.add_argument("--chunk-epochs", type=int, default=2, help="epochs per resume (2)")
    c.add_argument("--max-epochs", type=int, default=200, help="epochs cap per run (200)")
    c.add_argument("--tolerance", type=float, default=0.005, help="plateau tolerance (0.005)")
    c.add_argument("--patience", type=int, default=3, help="plateau epochs (3)")
    c.add_argument("--rule", choices=("updates", "cpu"), default="updates",
                   help="updates: every configuration trains the budget's updates, the best "
                   "at them is chosen (the ablation table's rule); cpu: the best at equal CPU "
                   "is chosen and the budget is its own plateau or cap (default: updates)")
    c.add_argument("--no-train", action="store_true",
                   help="fix the budget from the runs as they are (train nothing more)")
    c.add_argument("--precision", default="auto",
                   help="bsp-train --precision of every run (auto); pin the precision of the "
                   "table row the curve is for (e.g. bf16-mixed): auto's probe can choose "
                   "otherwise on a loaded machine")
    c.add_argument("--flip-test", action="store_true",
                   help="validate with the test-time flip (hp flip_test), as a row that uses it "
                   "is scored")
    c.add_argument("--smoke", action="store_true", help="plumbing only: tiny chunks, 1 seed")
    t = sub.add_parser("table", help="write the ablation table from OUT/budget.json again")
    t.add_argument("--out", default="runs/pose_budget")
    args = ap.parse_args(argv)
    if args.stage == "table":
        out = Path(args.out)
        write_table(out, json.loads((out / "budget.json").read_text()))
        return 0
    if args.smoke:
        args.seeds, args.widths, args.chunk_epochs = 1, [4], 1
        args.max_epochs, args.patience, args.jobs = 2, 1, 1
    return curves(args)


if __name__ == "__main__":
    sys.exit(main())
