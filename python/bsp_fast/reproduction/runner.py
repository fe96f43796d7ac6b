"""The one runner of ``bsp-reproduce``: every row of a table trained with N training seeds
(weights, batch order, noise draws; with ``--split-seeds`` also the recording split; runs
in ``OUT/TABLE-BUDGET/ROW/seed-S/``; N = 1 is a table of one seed, nothing apart), the
runs as parallel processes of one torch thread each (one :mod:`.worker` per job slot, kept
from run to run), finished runs reused and interrupted ones continued; the table's budget
rule checked. One result shape (:func:`run_table`); the statistics over seeds and
recordings are :mod:`.evidence`'s, the report :mod:`.report`'s. See docs/reproduce.md.

Configs go to ``OUT/TABLE-BUDGET/configs/ROW-seed-S.yaml``, each usable as ``bsp-train
--config``. Every run is recorded under the table file's protocol hash (:mod:`.protocol`,
``OUT/TABLE-BUDGET/protocol.json``); runs of another hash are not mixed in unless
``allow_changed``.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..atomic import write_text
from ..defaults import SEED
from ..training import config as C
from ..training.runs import PER_RECORDING_FILE as BREAKDOWN
from ..training.runs import RunError, read_run, resumable
from .cost import run_cost
from .noisy_boxes import noisy_box_metrics
from .protocol import guard, record_runs
from .restore import RESTORED_KEY, restorable
from .table_files import (BUDGETS, RULE_KEYS, check_budget_rule, load_table, prepare_row_data,
                          row_options, wanted_rows)

__all__ = ["RULE_KEYS", "check_budget_rule", "seed_list", "run_table", "plan_table",
           "collect_table", "TablePlan", "add_options"]

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
                        "test recordings, findings marked from the seed and recording variance "
                        "components' t test "
                        "(default: 1, a table of one seed, nothing marked)")
    p.add_argument("--split-seeds", action="store_true",
                   help="with --seeds: set the converter's split seed to the seed too (needs "
                        "a dataset directory; it shuffles the clips inside each split, the "
                        "recordings of each split stay the same; default: fixed)")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="with --seeds: runs trained at once, one process and one torch "
                        "thread each (default: the number of cores)")


def row_seeds(row: dict, seeds, budget: str):
    """The seeds ``row`` is trained with: ``seeds``, or its first ``max_seeds[budget]`` (a
    row whose cost per seed the table file gives as the reason)."""
    cap = (row.get("max_seeds") or {}).get(budget)
    return seeds if cap is None else seeds[:cap]


def _plan(tab, data, budget, base: Path, wanted, seeds, split_seeds, overrides, threads,
          convert: bool = True):
    """``[(row, seed, run_dir, opts)]``: one run per row and seed in ``ROW/seed-S/``."""
    plan = []
    for row, seed, name in _runs(tab, wanted, seeds, budget):
        extra = dict(overrides or {})
        run_dir = base / name
        extra["seed"] = seed
        if split_seeds:
            extra["split_seed"] = seed
        if threads:
            extra["threads"] = threads
        opts = row_options(tab, row, budget, data, run_dir, extra)
        C.validate(C.defaults() | opts)  # unknown models / hyper-parameters fail first
        opts = prepare_row_data(tab, row, opts, convert=convert)
        plan.append((row, seed, run_dir, opts))
    return plan


def _runs(tab, wanted, seeds, budget: str):
    """``(row, seed, name)`` of each run of the ``wanted`` rows (an ``initial_of`` row has
    none): ``name`` is ``ROW/seed-S``, as the run folders and the protocol ledger name
    them."""
    for row in tab["rows"]:
        if row["name"] in wanted and not row.get("initial_of"):
            for seed in row_seeds(row, seeds, budget):
                yield row, seed, f"{row['name']}/seed-{seed}"


def _convert_once(plan) -> None:
    """Converts each distinct dataset conversion before the parallel runs start (two
    processes must not write the same cache file)."""
    from ..training.setup import make_datamodule, prepare_data

    done = set()
    for _, _, _, opts in plan:
        cfg = C.defaults() | opts
        key = (cfg["data"], cfg["split_seed"], cfg["clip_length"], cfg["benchmark"])
        if key not in done:
            prepare_data(make_datamodule(cfg), stages=())
            done.add(key)


def _job(cfg_path, quiet: bool, stopped=None) -> dict:
    """A worker's job (:mod:`.worker`): ``bsp-train --config CFG --force`` of this very
    package, or ``--resume RUN`` of an interrupted run."""
    return {"resume": str(stopped), "quiet": quiet} if stopped is not None else \
        {"config": str(cfg_path), "quiet": quiet}


def _env() -> dict:
    import bsp_fast

    env = dict(os.environ)
    root = str(Path(bsp_fast.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in
                                                  env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


class _Worker:
    """One :mod:`.worker` process (imports nothing from this one: no forked torch or HDF5
    state) that trains the runs it is sent one at a time; its stderr goes to a temporary
    file whose tail a failure quotes."""

    def __init__(self, env: dict, quiet: bool):
        import subprocess
        import tempfile

        from .worker import command

        read, write = os.pipe()
        self.err = tempfile.TemporaryFile(mode="w+")
        try:
            self.proc = subprocess.Popen(command(write), env=env, stdin=subprocess.PIPE,
                                         stdout=subprocess.DEVNULL if quiet else None,
                                         stderr=self.err, pass_fds=(write,), text=True)
        finally:
            os.close(write)
        os.set_blocking(read, False)
        self.answers, self.buffer, self.job = read, b"", None

    def send(self, name: str, job: dict) -> None:
        self.job = (name, time.perf_counter())
        try:
            self.proc.stdin.write(json.dumps(job) + "\n")
            self.proc.stdin.flush()
        except BrokenPipeError:  # it died after its last run
            self.proc.wait()
            raise RunError(f"{name}: the training process exited with "
                           f"{self.proc.returncode} before this run:\n{self.tail()}") from None

    def answer(self):
        """The finished run's exit status, or None while it trains; RunError when the
        worker died without answering."""
        try:
            self.buffer += os.read(self.answers, 4096)
        except BlockingIOError:
            pass
        if b"\n" in self.buffer:
            line, self.buffer = self.buffer.split(b"\n", 1)
            return int(json.loads(line)["code"])
        if self.proc.poll() is not None:
            raise RunError(f"{self.job[0]}: the training process exited with "
                           f"{self.proc.returncode}:\n{self.tail()}")
        return None

    def tail(self) -> str:
        self.err.flush()
        self.err.seek(0)
        return self.err.read()[-2000:]

    def close(self, stop: bool) -> None:
        """Ends the worker: end of input when idle, SIGTERM (the run saves and stops at a
        batch end, resumable) when ``stop``."""
        try:
            if stop and self.proc.poll() is None:
                self.proc.terminate()
            self.proc.stdin.close()
        except OSError:  # it is gone already
            pass
        self.proc.wait()
        os.close(self.answers)
        self.err.close()


def _run(todo, jobs: int, quiet: bool, log) -> None:
    """Trains ``todo`` (``(name, config path, interrupted run or None)``) in up to
    ``jobs`` worker processes at once, each kept for the next run (:mod:`.worker`)."""
    if jobs <= 1:  # in this process, one run after the other
        from ..training.train import train

        for name, cfg_path, stopped in todo:
            t0 = time.perf_counter()
            if stopped is not None:  # interrupted or killed: continue, not restart
                log(f"[{name}] continuing the interrupted run {stopped}")
                train(resume=str(stopped), quiet=quiet)
            else:
                log(f"[{name}] training: bsp-train --config {cfg_path}")
                train(config=str(cfg_path), force=True, quiet=quiet)
            log(f"[{name}] done in {time.perf_counter() - t0:.0f} s")
        return
    pending, env = list(todo), _env()
    workers = [_Worker(env, quiet) for _ in range(min(jobs, len(pending)))]
    failed = True
    try:
        while pending or any(w.job for w in workers):
            for w in workers:
                if w.job is None and pending:
                    name, cfg_path, stopped = pending.pop(0)
                    if stopped is not None:  # interrupted or killed: continue, not restart
                        log(f"[{name}] continuing the interrupted run {stopped}")
                    w.send(name, _job(cfg_path, quiet, stopped))
            time.sleep(0.2)
            for w in workers:
                if w.job is None:
                    continue
                code = w.answer()
                if code is None:
                    continue
                name, t0 = w.job
                w.job = None
                if code != 0:
                    raise RunError(f"{name}: bsp-train exited with {code}:\n{w.tail()}")
                log(f"[{name}] done in {time.perf_counter() - t0:.0f} s")
        failed = False
    finally:
        for w in workers:  # only the processes started here
            w.close(stop=failed)


def _run_names(tab, wanted, seeds, base: Path, budget: str) -> dict:
    """``{name: run_dir}`` of the runs of ``wanted`` rows: name ``ROW/seed-S``, as the
    protocol ledger records them."""
    return {name: base / name for _, _, name in _runs(tab, wanted, seeds, budget)}


def _seconds(run_dir: Path, seconds: dict) -> dict:
    """The run's recorded seconds, marked ``partial`` where its fit time covers only its
    last process: resumed (several CSV log versions) before fit seconds were carried over
    resumes (no ``carried`` key)."""
    resumed = len(list((run_dir / "logs").glob("version_*"))) > 1
    if seconds and resumed and not seconds.get("carried"):
        return dict(seconds, partial=True)
    return seconds


def _seed_result(run_dir: Path) -> dict:
    run = read_run(run_dir)
    m = run["metrics"]
    return {"metrics": m.get("test", {}), "initial": (m.get("initial") or {}).get("test", {}),
            "baseline": (m.get("initial") or {}).get("baseline"), "epochs": m.get("epochs"),
            "best_epoch": m.get("best_epoch"),
            "seconds": _seconds(run_dir, m.get("seconds", {})),
            "precision": m.get("precision"), "run": str(run_dir),
            "per_recording": str(run_dir / BREAKDOWN) if (run_dir / BREAKDOWN).is_file()
            else None, "noise": run["config"].get("noise"), "mjp": run["config"].get("mjp"),
            "machine": run["config"].get("machine")}


@dataclass
class TablePlan:
    """What a table's call will do, decided before any training: the rows and seeds, each
    run's folder, config file and fate (read from a published table, reused, trained),
    and the protocol record they are checked against."""
    tab: dict
    budget: str
    base: Path  # OUT/TABLE-BUDGET
    data: object
    seeds: list  # one seed or more, each row's runs in ROW/seed-S
    split_seeds: bool
    jobs: int
    wanted: list
    names: dict  # {run name: run folder}
    restored: dict  # {run name: (result, protocol record, cost)} from --with-published
    protocol: dict
    ledger: dict
    runs: list = field(default_factory=list)  # (row, seed, run_dir, opts)
    todo: list = field(default_factory=list)  # (label, config file, stopped run or None)
    fresh: list = field(default_factory=list)  # run names trained from scratch
    slow: list = field(default_factory=list)  # rows in bf16 on a CPU


def run_table(table, data, budget: str = "quick", out="runs", *, seeds: int = 1,
              split_seeds: bool = False, jobs: int | None = None, rows=None, overrides=None,
              force: bool = False, quiet: bool = True, dry_run: bool = False,
              allow_changed: bool = False, with_published=None, log=print) -> dict:
    """Trains the rows of ``table`` (all, or the names in ``rows``), reusing finished runs
    unless ``force``, and returns ``{"table", "budget", "dir", "data", "seeds",
    "split_seeds", "protocol", "results": {row: {"seeds": {seed: {...one run...}},
    "source", "noise", "mjp", "cost"}}}``: :func:`plan_table`, then the training of what
    the plan leaves to train (:func:`_train_planned`), then :func:`collect_table`.

    Before anything is written, the runs it would reuse or continue are checked against
    the folder's protocol ledger (:func:`.protocol.guard`): one made under another version
    of the table file or other ``overrides`` raises :class:`.protocol.ProtocolChanged`
    unless ``allow_changed`` (then the mix is recorded in ``protocol["mixed"]``).

    ``seeds=N``: N training seeds per row (the default seed and the N - 1 after it) in
    ``ROW/seed-S/``; one seed is a table of one seed, the same result shape (its findings
    read from the one run's values, :func:`.report.findings_of`). ``jobs`` processes at
    once (default: one for one seed, else the cores; one torch thread each when ``jobs``
    > 1); the statistics are
    :func:`.evidence.summarise`'s.

    ``with_published=DIR`` (with seeds): the runs of the wanted rows with no run here are
    read from the published table in ``DIR`` where it has them (:mod:`.restore`), under
    their own protocol record; ``protocol["restored"]`` names them."""
    plan = plan_table(table, data, budget, out, seeds=seeds, split_seeds=split_seeds,
                      jobs=jobs, rows=rows, overrides=overrides, force=force,
                      dry_run=dry_run, allow_changed=allow_changed,
                      with_published=with_published, log=log)
    out_res = {"table": plan.tab["table"], "budget": budget, "dir": str(plan.base),
               "data": str(data), "seeds": plan.seeds, "split_seeds": bool(split_seeds),
               "results": {}}
    if dry_run:
        return out_res
    record_runs(plan.base, plan.protocol, plan.ledger, plan.fresh)  # interrupted runs count
    out_res["protocol"] = dict(plan.protocol,
                               runs={n: plan.ledger["runs"].get(n) for n in plan.names})
    if plan.restored:
        out_res["protocol"]["restored"] = sorted(plan.restored)
    _train_planned(plan, quiet, log)
    out_res["results"] = collect_table(plan, force, quiet, log)
    return out_res


def _check_call(budget: str, seed_values, jobs, split_seeds: bool, data) -> int:
    """The call's arguments checked; returns the processes to train with."""
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {list(BUDGETS)}, got {budget!r}")
    if jobs is None:  # one seed: one process, its torch threads on every core
        jobs = 1 if len(seed_values) == 1 else (os.cpu_count() or 1)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an integer >= 1, got {jobs!r}")
    if split_seeds and Path(data).suffix in (".h5", ".hdf5"):
        raise ValueError("--split-seeds needs a dataset directory: an HDF5 file holds one "
                         "split")
    return jobs


def plan_table(table, data, budget: str, out, *, seeds=1, split_seeds=False, jobs=None,
               rows=None, overrides=None, force=False, dry_run=False, allow_changed=False,
               with_published=None, log=print) -> TablePlan:
    """The :class:`TablePlan` of a call of :func:`run_table`; writes each run's config
    file (``bsp-train --config``), nothing else."""
    tab = table if isinstance(table, dict) else load_table(table)
    seed_values = seed_list(seeds)
    jobs = _check_call(budget, seed_values, jobs, split_seeds, data)
    wanted = wanted_rows(tab, rows or _not_moved(tab, budget, log))
    base = Path(out) / f"{tab['table']}-{budget}"
    names = _run_names(tab, wanted, seed_values, base, budget)
    kept = [n for n, d in names.items()  # reused or continued, not retrained
            if not force and ((d / "metrics.json").is_file() or resumable(d) is not None)]
    restored = {}
    if with_published is not None:
        restored = restorable(tab, budget, with_published, data, split_seeds,
                              [n for n in names if n not in kept and not force])
    protocol, ledger = guard(base, tab, budget, [*kept, *restored], overrides,
                             allow_changed=allow_changed,
                             known={n: rec for n, (_, rec, _) in restored.items()})
    plan = TablePlan(tab, budget, base, data, seed_values, bool(split_seeds), jobs, wanted,
                     names, restored, protocol, ledger)
    plan.runs = _plan(tab, data, budget, base, wanted, seed_values, split_seeds, overrides,
                      1 if jobs > 1 else None, convert=not dry_run)
    for run in plan.runs:
        _decide(plan, run, force, dry_run, log)
    return plan


def _not_moved(tab: dict, budget: str, log) -> list | None:
    """The rows of ``budget``: a row whose ``moved: {to: ...}`` names another budget is
    that budget's (said once; ``--rows`` still runs it on purpose). None: every row."""
    moved = [r["name"] for r in tab["rows"]
             if (r.get("moved") or {}).get("to") not in (None, budget)]
    if not moved:
        return None
    log(f"rows {', '.join(moved)} are registered in another budget (moved:) and are not "
        f"run in {budget!r}; --rows runs them on purpose")
    return [r["name"] for r in tab["rows"] if r["name"] not in moved]


def _decide(plan: TablePlan, run, force: bool, dry_run: bool, log) -> None:
    """Writes one run's config file and files the run under what will happen to it."""
    import yaml

    row, seed, run_dir, opts = run
    run_name = str(run_dir.relative_to(plan.base))  # as the ledger and `restored` name it
    label = f"{row['name']} seed {seed}"
    cfg_path = plan.base / "configs" / f"{row['name']}-seed-{seed}.yaml"
    cfg_path.parent.mkdir(parents=True, exist_ok=True)
    write_text(cfg_path, "# bsp-reproduce: one row and seed, usable as bsp-train --config\n"
               + yaml.safe_dump(opts, sort_keys=False))
    if dry_run:
        log(f"bsp-train --config {cfg_path}")
    elif run_name in plan.restored:
        log(f"[{label}] read from the published {plan.restored[run_name][1][RESTORED_KEY]}")
    elif (run_dir / "metrics.json").is_file() and not force:
        log(f"[{label}] reusing {run_dir} (--force to train again)")
    else:  # an interrupted run of an earlier call continues (unless --force)
        plan.todo.append((label, cfg_path, None if force else resumable(run_dir)))
        if plan.todo[-1][2] is None:
            plan.fresh.append(run_name)
        if str(opts.get("precision")).startswith("bf16") and \
                opts.get("accelerator", "cpu") == "cpu":
            plan.slow.append(row["name"])


def _train_planned(plan: TablePlan, quiet: bool, log) -> None:
    """Trains (or continues) every run the plan left to train."""
    if plan.slow:
        from ..training.precision import native_bf16

        if not native_bf16("cpu"):  # said once, before hours of training, not per run
            log(f"note: rows {', '.join(dict.fromkeys(plan.slow))} are set to bf16-mixed (by "
                "the table file or --set), and this CPU has no native bf16 (AVX512-BF16/"
                "AMX): they train several times slower than in float32 (x0.06-x0.20 "
                "measured for the convolutional and transformer models; docs/performance.md,"
                " 'A real AVX2-only CPU'). --set precision=32 trains them in float32, "
                "recorded as other options (docs/reproduce.md, 'Registered protocol')")
    if not plan.todo:
        return
    if plan.jobs > 1:
        _convert_once(plan.runs)
        log(f"training {len(plan.todo)} run(s), {min(plan.jobs, len(plan.todo))} at a time")
    _run(plan.todo, plan.jobs, quiet, log)


def collect_table(plan: TablePlan, force: bool, quiet: bool, log) -> dict:
    """``{row: {"seeds": {seed: one run}, "source", "noise", "mjp", "cost"}}`` of the
    planned runs, read back from their folders (or the published table)."""
    results, published_cost = {}, {}
    for row, seed, run_dir, _ in plan.runs:
        r = results.setdefault(row["name"], {"seeds": {}, "source": "test"})
        back = plan.restored.get(str(run_dir.relative_to(plan.base)))
        if back:  # published with its noisy-box scores, where the table has them
            r["seeds"][str(seed)] = one = back[0]
            published_cost.setdefault(row["name"], back[2])
        else:
            r["seeds"][str(seed)] = one = _seed_result(run_dir)
            one["metrics"].update(noisy_box_metrics(plan.tab, run_dir, force, quiet, log))
        r["noise"], r["mjp"] = one["noise"], one["mjp"]
    for name, r in results.items():  # parameters and FLOPs of the row's model, its first run
        first = next(iter(r["seeds"].values()))["run"]
        r["cost"] = run_cost(first) if first else published_cost.get(name, {})
    _initial_rows(plan, results)
    return results


def _initial_rows(plan: TablePlan, results: dict) -> None:
    """Rows read from another row's trivial baseline (``initial_of``)."""
    for row in plan.tab["rows"]:
        src = row.get("initial_of")
        if row["name"] in plan.wanted and src and src in results:
            r = results[row["name"]] = dict(results[src], source="initial", run_of=src)
            r["cost"] = {}  # no model of its own


