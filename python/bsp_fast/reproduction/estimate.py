"""``bsp-reproduce TABLE --data DATASET --estimate``: what a table costs before it runs
(issue #57). Each row's CPU minutes per seed from a short timed probe on this machine, and
the table's total (every row at its seeds) against the CPU budget a registered quick
table must fit: :data:`BUDGET_CPU_HOURS` on an AVX2-only core.

The probe, per row (its resolved ``bsp-train`` options, the row's data converted as a run
converts it): a few optimiser updates of the row's model on batches drawn from its train
loader (loading included), and a few validation batches (forward and loss, no gradient),
each timed in this process's CPU seconds (``time.process_time``: all its threads, what
other processes on the same cores barely change). A seed's cost is then the budget's cap
of updates (``max_steps``, or epochs x train batches when that ends first) times the
update, plus every validation pass those epochs make, the initial metrics' pass over val
and test and the test pass (twice for a table with noisy-box metrics) times the
validation batch, plus :data:`STARTUP_S` a run (imports, checkpoints, figures). It is an
upper bound: early stopping may end a run sooner.

AVX2-only cores. The probe times the precision the row trains in; a registered quick
budget trains in float32 (``precision: "32"``), whose speed does not depend on bf16
instructions, so a float32 probe on an AVX512-BF16 CPU translates to an AVX2-only one by
the measured float32 ratio of the two kinds of core (:data:`AVX2_FLOAT32_FACTOR`, per
model, from docs/performance.md "A real AVX2-only CPU"; :data:`AVX2_DEFAULT_FACTOR` for a
model not measured there). On a CPU without AVX512 the factor is 1. bf16 on an AVX2-only
core costs 5-17x float32 (the same measurements): such rows are flagged, never
translated.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

__all__ = ["BUDGET_CPU_HOURS", "AVX2_FLOAT32_FACTOR", "AVX2_DEFAULT_FACTOR", "FIVE_MINUTES", "AVX2_FLOAT32_STEP",
           "cpu_kind", "seed_cost", "probe_row", "estimate_table",
           "registered_seeds", "row_seed_counts", "moved_rows", "test_scale", "STARTUP_S",
           "main_estimate"]

#: a registered quick table, all rows and seeds, fits this many CPU hours on an AVX2 core
BUDGET_CPU_HOURS = 8.0
#: a row under this many CPU seconds per seed (AVX2 core) gets 10 seeds (issue #57)
FIVE_MINUTES = 300.0
#: CPU seconds a run spends outside its updates and evaluation passes: imports (Lightning
#: 3-5 s), the trivial baseline, checkpoints, the per-recording breakdown and the curves
#: figure (docs/performance.md, "bsp-train against the plain loop": 4-5 s of start-up, 0.3-1
#: s of breakdown, 0.6 s of figure, 0.4 s of fsync in a 40-epoch run)
STARTUP_S = 8.0
#: float32 seconds per step, AVX2-only EPYC / AVX512-BF16 EPYC, per ``task/model``: the
#: step probe of both machines (docs/performance.md, "A real AVX2-only CPU" (2026-11-27),
#: benchmarks/results/avx2-2026-11-27/bench_precision_probe.md)
AVX2_FLOAT32_FACTOR = {
    "classification/lstm": 30.4 / 6.9,
    "classification/pedestrian_graph": 110.8 / 59.2,
    "autoencoder/simple_transformer": 534.2 / 267.2,
    "lifting/baseline_3d": 694.5 / 391.8,
    "lifting/lstm": 17.3 / 8.2,
    "lifting/lstm_relative_rot": 36.3 / 16.2,
    "lifting/poseformer": 5320.9 / 3789.4,
    "pose_estimation/pose_cnn": 187.8 / 110.2,
    "pose_estimation/pose_temporal": 923.8 / 412.9,
}
#: the AVX2-only EPYC's own float32 step, ``(batch, ms)``, from the same probe: where a row
#: trains that model at that batch, an update is taken as at least this long there (this
#: machine's step x the ratio could be shorter when this machine is quieter than it was)
AVX2_FLOAT32_STEP = {
    "classification/lstm": (64, 30.4), "classification/pedestrian_graph": (64, 110.8),
    "autoencoder/simple_transformer": (32, 534.2), "lifting/baseline_3d": (64, 694.5),
    "lifting/lstm": (64, 17.3), "lifting/lstm_relative_rot": (64, 36.3),
    "lifting/poseformer": (16, 5320.9), "pose_estimation/pose_cnn": (8, 187.8),
    "pose_estimation/pose_temporal": (4, 923.8),
}
#: for a model not measured on both: the largest ratio of the models above but the LSTM's
#: (a tiny model whose steps are mostly overhead, x4.4)
AVX2_DEFAULT_FACTOR = 2.24


def cpu_kind() -> dict:
    """``{"model", "avx512", "bf16"}`` of this machine's CPU (from /proc/cpuinfo)."""
    model, flags = "unknown CPU", set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and model == "unknown CPU":
                model = value.strip()
            elif key.strip() == "flags" and not flags:
                flags = set(value.split())
    except OSError:
        pass
    return {"model": model, "avx512": "avx512f" in flags,
            "bf16": bool({"avx512_bf16", "amx_bf16"} & flags)}


def avx2_factor(task: str, model: str, precision: str, cpu: dict, step_s: float | None = None,
                batch: int | None = None, default_hp: bool = True) -> float | None:
    """This machine's CPU seconds -> an AVX2-only core's: 1 on a CPU without AVX512, the
    measured float32 ratio otherwise (at least the AVX2 core's own measured step over this
    probe's, for the model with its default hyper-parameters at the batch it was measured
    at: :data:`AVX2_FLOAT32_STEP`);
    None for bf16 (not translated: 5-17x slower there)."""
    if str(precision).startswith("bf16"):
        return None
    if not cpu.get("avx512"):
        return 1.0
    key = f"{task}/{model}"
    factor = AVX2_FLOAT32_FACTOR.get(key, AVX2_DEFAULT_FACTOR)
    at = AVX2_FLOAT32_STEP.get(key)
    if at is not None and step_s and batch == at[0] and default_hp:
        factor = max(factor, at[1] / 1000.0 / step_s)
    return factor


def seed_cost(step_s: float, eval_s: float, *, train_batches: int, val_batches: int,
              test_batches: int, epochs: int, max_steps: int | None,
              test_passes: int = 1, test_scale: float = 1.0) -> dict:
    """CPU seconds of one seed of a row from its probe: ``{"updates", "epochs", "train_s",
    "eval_s", "total_s"}`` (the budget's cap: early stopping may end sooner).
    ``test_scale``: the test pass(es) on a registered test set this many times the size of
    the data's own test split (the initial metrics still read the data's own)."""
    per_epoch = max(int(train_batches), 1)
    updates = epochs * per_epoch
    if max_steps:
        updates = min(updates, int(max_steps))
    run_epochs = max(1, math.ceil(updates / per_epoch))
    # validation after every epoch; the initial metrics' val and test pass; the test
    # pass(es) of the best checkpoint
    evals = (run_epochs * val_batches + val_batches + test_batches
             + test_batches * test_passes * test_scale)
    train = updates * step_s
    ev = evals * eval_s
    return {"updates": updates, "epochs": run_epochs, "train_s": train, "eval_s": ev,
            "total_s": train + ev + STARTUP_S}


def moved_rows(tab: dict, budget: str) -> dict:
    """``{row: why}`` of the rows the table file moved off ``budget`` (``moved: {to: full,
    when, why}``: they train on their ``to`` budget only)."""
    out = {}
    for row in tab["rows"]:
        moved = row.get("moved")
        if isinstance(moved, dict) and moved.get("to") != budget and budget in (
                moved.get("from") or ["quick"]):
            out[row["name"]] = str(moved.get("why") or "")
    return out


def test_scale(tab: dict) -> float:
    """How many times its data's own test split the registered test set is
    (``design: {test_set: {scale: K}}``), else 1."""
    ts = (tab.get("design") or {}).get("test_set") or {}
    scale = ts.get("scale", 1) if isinstance(ts, dict) else 1
    return float(scale) if isinstance(scale, (int, float)) and scale > 0 else 1.0


def registered_seeds(tab: dict, budget: str) -> int | None:
    """The seed count the table file registers for ``budget`` (``design: {seeds: {quick:
    10}}``), else None."""
    seeds = ((tab.get("design") or {}).get("seeds") or {})
    n = seeds.get(budget) if isinstance(seeds, dict) else None
    return int(n) if isinstance(n, int) and not isinstance(n, bool) and n >= 1 else None


def row_seed_counts(tab: dict, budget: str, seeds: int) -> dict:
    """``{row: seeds it trains}``: ``seeds`` capped by the row's ``max_seeds``."""
    out = {}
    for row in tab["rows"]:
        cap = (row.get("max_seeds") or {}).get(budget)
        out[row["name"]] = seeds if cap is None else min(seeds, cap)
    return out


def _batches(loader, n: int):
    """Up to ``n`` batches, the loader restarted when it ends first."""
    got = 0
    while got < n:
        empty = True
        for batch in loader:
            empty = False
            yield batch
            got += 1
            if got >= n:
                return
        if empty:
            return


def _timed(loader, n: int, step) -> list:
    """CPU seconds of ``step(batch)`` for ``n`` batches, each including its loading."""
    clock, times = time.process_time, []
    it = iter(_batches(loader, n))
    while True:
        t0 = clock()
        try:
            batch = next(it)
        except StopIteration:
            return times
        step(batch)
        times.append(clock() - t0)


def _probe_options(tab: dict, row: dict, budget: str, data, overrides) -> tuple:
    """``(opts, row, note)``: the row's run options; a sibling dataset not made yet
    (data_variants) is stood in for by --data, the same preset's shapes (said beside the
    row in ``note``)."""
    from .table_files import row_options

    with tempfile.TemporaryDirectory(prefix="bsp-estimate-") as tmp:
        opts = row_options(tab, row, budget, data, Path(tmp) / row["name"], overrides)
    note = None
    if row.get("data_suffix") and not Path(opts["data"]).exists():
        note = f"probed on --data: {opts['data']} not made yet"
        opts["data"] = str(data)
        row = {k: v for k, v in row.items() if k != "data_suffix"}
    return opts, row, note


def _steps(module, cfg: dict, bf16: bool) -> tuple:
    """``(train_step, eval_step)`` of a run's net: one optimiser update, and one
    validation batch (forward, loss and the metrics)."""
    import torch

    from ..training.scoring import eval_step as score_step

    net = module.net
    opt = net.configure_optimizers(lr=cfg["lr"], total_steps=cfg.get("max_steps") or None)
    opt = opt["optimizer"]

    def train_step(batch):
        net.train()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            loss = net.loss(net.forward_batch(batch), batch)
        opt.zero_grad(set_to_none=True)
        loss.float().backward()
        opt.step()

    def eval_step(batch):
        net.eval()
        with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            score_step(module.spec, net, batch, module.val_metrics)

    return train_step, eval_step


def probe_row(tab: dict, row: dict, budget: str, data, overrides=None, *, steps: int = 4,
              eval_batches: int = 3, log=print) -> dict:
    """Times one row (see the module's docstring): ``{"model", "precision", "threads",
    "step_s", "eval_s", "train_batches", "val_batches", "test_batches", "epochs",
    "max_steps", "convert_s"}``."""
    import statistics

    import torch

    from ..training import config as C
    from ..training.module import TASK_MODULES
    from ..training.precision import resolve_precision
    from ..training.setup import make_datamodule, prepare_data
    from .table_files import prepare_row_data

    opts, row, note = _probe_options(tab, row, budget, data, overrides)
    t0 = time.process_time()
    opts = prepare_row_data(tab, row, opts)
    cfg = C.defaults() | opts
    if cfg["threads"]:
        torch.set_num_threads(int(cfg["threads"]))
    torch.manual_seed(int(cfg["seed"]))
    dm = make_datamodule(cfg)
    prepare_data(dm, stages=("fit", "test"))
    convert_s = time.process_time() - t0
    module = TASK_MODULES[cfg["task"]](cfg["model"], hparams=cfg["hp"], lr=cfg["lr"],
                                       config=cfg)
    net = module.net
    precision = resolve_precision(cfg["precision"], cfg["accelerator"], net)
    bf16 = precision.startswith("bf16")
    train_loader, val_loader = dm.train_dataloader(), dm.val_dataloader()
    counts = {"train_batches": len(train_loader), "val_batches": len(val_loader),
              "test_batches": len(dm.test_dataloader())}
    if cfg.get("limit_batches"):
        counts = {k: min(v, int(cfg["limit_batches"])) for k, v in counts.items()}
    train_step, eval_step = _steps(module, cfg, bf16)
    first = _timed(train_loader, 1, train_step)  # warm-up (allocations, first kernels)
    n = 2 if first and first[0] > 5.0 else steps  # a slow model: 2 timed updates
    step_s = statistics.median(_timed(train_loader, n, train_step))
    _timed(val_loader, 1, eval_step)
    eval_s = statistics.median(_timed(val_loader, max(1, eval_batches), eval_step))
    from ..models import catalogue

    defaults = catalogue.hparams(cfg["task"], cfg["model"])
    default_hp = all(defaults.get(k, object()) == v for k, v in (cfg["hp"] or {}).items())
    return {"model": cfg["model"], "task": cfg["task"], "precision": precision,
            "default_hp": default_hp,
            "threads": int(cfg["threads"] or torch.get_num_threads()), "step_s": step_s,
            "eval_s": eval_s, **counts, "epochs": int(cfg["epochs"]),
            "max_steps": int(cfg.get("max_steps") or 0) or None, "convert_s": convert_s,
            "batch_size": int(cfg["batch_size"]), "note": note}


def estimate_table(tab: dict, data, budget: str = "quick", *, seeds: int | None = None,
                   rows=None, overrides=None, steps: int = 4, eval_batches: int = 3,
                   log=print) -> dict:
    """Probes every wanted row (a row that reads another row's run costs nothing of its
    own) and returns ``{"table", "budget", "seeds", "cpu", "rows": {name: {...probe,
    "seeds", "per_seed_s", "per_seed_avx2_s", "total_avx2_s"}}, "total_s", "total_avx2_s",
    "budget_s", "fits", "cheap", "startup_s"}`` (rendered by
    :func:`bsp_fast.reporting.estimate.format_estimate`)."""
    from .table_files import wanted_rows

    n_seeds = seeds or registered_seeds(tab, budget) or 5
    counts = row_seed_counts(tab, budget, n_seeds)
    cpu = cpu_kind()
    test_passes = 2 if any(m.endswith("_noisy") for m in tab["metrics"]) else 1
    out = {"table": tab["table"], "budget": budget, "seeds": n_seeds, "cpu": cpu, "rows": {},
           "budget_s": BUDGET_CPU_HOURS * 3600.0}
    by_name = {r["name"]: r for r in tab["rows"]}
    moved, scale = moved_rows(tab, budget), test_scale(tab)
    out["moved"], out["test_scale"] = moved, scale
    for name in wanted_rows(tab, rows):
        row = by_name[name]
        if name in moved:
            continue
        if row.get("initial_of"):
            out["rows"][name] = {"reads": row["initial_of"], "seeds": counts[name],
                                 "per_seed_s": 0.0, "per_seed_avx2_s": 0.0,
                                 "total_avx2_s": 0.0, "total_s": 0.0}
            continue
        log(f"[{name}] probing ...")
        p = probe_row(tab, row, budget, data, overrides, steps=steps,
                      eval_batches=eval_batches, log=log)
        cost = seed_cost(p["step_s"], p["eval_s"], train_batches=p["train_batches"],
                         val_batches=p["val_batches"], test_batches=p["test_batches"],
                         epochs=p["epochs"], max_steps=p["max_steps"],
                         test_passes=test_passes, test_scale=scale)
        factor = avx2_factor(p["task"], p["model"], p["precision"], cpu, p["step_s"],
                             p["batch_size"], p["default_hp"])
        per_avx2 = None if factor is None else cost["total_s"] * factor
        out["rows"][name] = dict(p, updates=cost["updates"], epochs=cost["epochs"],
                                 train_s=cost["train_s"], seeds=counts[name],
                                 per_seed_s=cost["total_s"],
                                 avx2_factor=factor, per_seed_avx2_s=per_avx2,
                                 total_s=cost["total_s"] * counts[name],
                                 total_avx2_s=None if per_avx2 is None
                                 else per_avx2 * counts[name])
        log(f"[{name}] {p['precision']}: {p['step_s']:.3f} CPU s/update, "
            f"{p['eval_s']:.3f} CPU s/val batch -> {cost['total_s'] / 60:.1f} CPU min/seed")
    rs = out["rows"].values()
    out["total_s"] = sum(r["total_s"] for r in rs)
    unknown = [n for n, r in out["rows"].items() if r["total_avx2_s"] is None]
    out["bf16_rows"] = unknown
    out["total_avx2_s"] = None if unknown else sum(r["total_avx2_s"] for r in rs)
    out["fits"] = out["total_avx2_s"] is not None and out["total_avx2_s"] <= out["budget_s"]
    # the rows the 10-seed rule of issue #57 applies to, and the start-up each run counts
    out["cheap"] = [n for n, r in out["rows"].items() if "reads" not in r
                    and r["per_seed_avx2_s"] is not None
                    and r["per_seed_avx2_s"] < FIVE_MINUTES]
    out["startup_s"] = STARTUP_S
    return out


def main_estimate(tab: dict, data, budget: str, *, seeds: int | None, rows=None,
                  overrides=None, out=None, log=print) -> int:
    """The ``--estimate`` of ``bsp-reproduce``: prints the estimate (and writes it as JSON
    beside the runs' folder when ``out`` is given); exit status 0."""
    import json

    from ..reporting.estimate import format_estimate

    est = estimate_table(tab, data, budget, seeds=seeds, rows=rows, overrides=overrides,
                         log=log)
    print(format_estimate(est))
    if out is not None:
        path = Path(out) / f"{tab['table']}-{budget}.estimate.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(est, indent=1, default=str) + "\n", encoding="utf-8")
        print(f"written {path}")
    return 0
