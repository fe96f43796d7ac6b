"""``bsp-train TASK MODEL --data DATASET``: train a baseline, test it, write a run directory.

Python: ``bsp_fast.train("lifting", "martinez", data="clips.h5", epochs=30)`` returns a
:class:`TrainResult`. See docs/training.md.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from . import config as C
from ..command_line import error_hint, run_command
from ..atomic import atomic_output, remove
from .runs import ENV_TMP, MARKER, RunDirectory, RunError, default_run_dir, is_temporary, \
    open_run, read_marker, read_run, refuse_unsafe_output, resume_hint, write_json, \
    write_marker
from .precision import check_precision, decide_precision, kept_precision, machine_record, \
    probe_key, run_model_key, time_steps
from .setup import make_datamodule, make_trainer, prepare_data
from .tasks import TASKS, get_task

__all__ = ["train", "main", "TrainResult", "few_updates"]


@dataclass
class TrainResult:
    """What a run produced. ``metrics``: test metrics (mm for 3D); ``initial``: the trivial
    baseline's metrics on val and test; ``val``: val metrics of the best epoch."""
    run_dir: Path
    metrics: dict
    val: dict
    initial: dict
    best_checkpoint: Path
    last_checkpoint: Path
    best_epoch: int | None
    epochs: int
    config: dict
    seconds: dict = field(default_factory=dict)


# ---------------------------------------------------------------------- config
def resolve_config(cli: dict, config_path=None) -> tuple:
    """defaults < resumed run's config < --config YAML < explicit options ->
    ``(cfg, resume)`` with ``resume`` = ``{"ckpt", "run_dir"}`` or None."""
    from_yaml = C.read_yaml(config_path) if config_path else {}
    cfg = C.defaults()
    resume = None
    target = cli.get("resume", from_yaml.get("resume"))
    if target:
        opened = open_run(target, "last", f"--resume {target}: ")
        ckpt, run_dir, info, saved = (opened[k] for k in ("ckpt", "run_dir", "info", "config"))
        resolved = saved.get("resolved") or {}
        known = {k: v for k, v in saved.items() if k in C.BY_NAME
                 and k not in ("resume", "force", "out", "quiet")}
        if resolved.get("data") and known.get("data") and not Path(known["data"]).exists():
            known["data"] = resolved["data"]  # a relative path, resumed from elsewhere
        cfg.update(C.normalise(known, f"{target} (saved config)"))
        orphan = run_dir is not None and is_temporary(run_dir)
        resume = {"ckpt": Path(ckpt), "run_dir": run_dir,
                  "epoch": info.get("restored_epoch"),  # Lightning's current_epoch
                  "precision": kept_precision(saved)}  # auto's answer at its start
        if orphan:  # a killed run: it goes to the --out it was started with
            cfg["out"] = (read_marker(run_dir) or {}).get("out") or resolved.get("out")
        for key in ("task", "model"):
            want = cli.get(key, from_yaml.get(key))
            if want is not None and want != saved.get(key):
                raise C.ConfigError(f"--resume {target} is a {saved.get('task')!r} run of "
                                    f"model {saved.get('model')!r}; it cannot continue as "
                                    f"{key} {want!r}")
        if cli.get("out") is None and from_yaml.get("out") is None and run_dir is not None \
                and not orphan:
            cfg["out"] = str(run_dir)
    cfg.update(from_yaml)
    cfg.update(cli)
    cfg = C.validate(cfg)
    if cfg["out"] is None:
        cfg["out"] = str(default_run_dir(cfg["task"], cfg["model"]))
    return cfg, resume


# ---------------------------------------------------------------------- the run
def few_updates(cfg: dict, train_clips: int, least: int = 3) -> str | None:
    """Why the run will hardly learn, when its epochs hold fewer than ``least`` optimiser
    updates (e.g. the default batch of 256 over a 40-clip sample: one per epoch); None
    otherwise. The batch suggested gives about ten per epoch."""
    per_epoch = -(-train_clips // cfg["batch_size"])
    if per_epoch >= least or cfg.get("max_steps"):
        return None
    batch = 1 << max(0, (train_clips // 10).bit_length() - 1)  # a power of two
    return (f"{train_clips} train clips at --batch-size {cfg['batch_size']} make {per_epoch} "
            f"update(s) per epoch, {per_epoch * cfg['epochs']} in all: too few to learn "
            f"from; pass a smaller --batch-size (e.g. {batch}) or more --epochs")


# The run is a plan (decided before PyTorch is imported: options, inputs, outputs and this
# process's part in a multi-process run), an execution (model, data, precision, fit and
# test) and a collection (metrics.json, config.yaml, curves; _finish).
@dataclass
class RunPlan:
    cfg: dict  # the resolved options
    resume: dict | None  # the run or checkpoint this one continues (resolve_config)
    config_path: object  # --config, an input --out must never replace
    #: a secondary DDP process: the first process's temporary run directory it writes to
    child_tmp: Path | None = None
    #: the temporary name every process of a user-started multi-process run shares
    shared: str | None = None


def _env_rank(env) -> int:
    """This process's rank as the launchers set it (Lightning's order of keys), and its
    machine's (NODE_RANK): > 0 for every process but the first."""
    ranks = [env.get(k) for k in ("RANK", "LOCAL_RANK", "SLURM_PROCID", "JSM_NAMESPACE_RANK")]
    first = next((r for r in ranks if r is not None), "0")
    node = env.get("NODE_RANK", "0")
    return max(int(x) if str(x).isdigit() else 0 for x in (first, node))


def plan_run(cli: dict, config_path=None, env=None) -> RunPlan:
    """The run's plan; ``env`` (default ``os.environ``) is read here once: the launcher's
    ranks, and the temporary run directory a first process hands its DDP processes."""
    env = os.environ if env is None else env
    cfg, resume = resolve_config(cli, config_path)
    plan = RunPlan(cfg, resume, config_path)
    # processes the user started (torchrun, or one bsp-train per machine with NODE_RANK and
    # --num-nodes) share a temporary name; Lightning's own DDP processes are handed theirs
    if "TORCHELASTIC_RUN_ID" in env or (cfg.get("num_nodes") or 1) > 1:
        plan.shared = f".{Path(cfg['out']).name}.tmp-ddp-{env.get('MASTER_PORT', '0')}"
    rank = _env_rank(env)
    handed = env.get(ENV_TMP) or (str(Path(cfg["out"]).absolute().with_name(plan.shared))
                                  if plan.shared else None)
    if handed and rank > 0:
        plan.child_tmp = Path(handed)
    if cfg.get("mix") is None and not Path(cfg["data"]).exists():
        raise RunError(f"{cfg['data']}: no such dataset directory or HDF5 file")
    if plan.child_tmp is None:  # before any work: --force never replaces an input
        refuse_unsafe_output(cfg["out"], force=cfg["force"], inputs=_inputs(plan),
                             in_place=resume["run_dir"] if resume is not None else None)
    return plan


def _train(cli: dict, config_path=None) -> TrainResult | None:
    from .stopping import signals

    plan = plan_run(cli, config_path)
    with signals() as sig:  # SIGINT/SIGTERM: Interrupted, deferred to batch ends in fit
        return _execute(plan, sig)


def _model_and_data(plan: RunPlan):
    """``(module, dm)``: the model first, so a bad --hp is refused before any data is
    converted (the data setup draws no random number: the weights are the seed's)."""
    import lightning.pytorch as pl
    import torch

    from .module import TASK_MODULES

    cfg = plan.cfg
    if cfg["threads"]:
        torch.set_num_threads(cfg["threads"])
    pl.seed_everything(cfg["seed"], workers=True, verbose=False)
    try:
        module = TASK_MODULES[cfg["task"]](cfg["model"], hparams=cfg["hp"], lr=cfg["lr"],
                                           config=cfg)
    except (ValueError, TypeError, AssertionError, RuntimeError) as exc:
        raise C.ConfigError(f"model {cfg['model']!r}: {exc}") from None
    if cfg.get("compile") == "on":
        # the bound method, not the module: checkpoints keep their keys (no "_orig_mod.");
        # static shapes: a short last batch compiles once more instead of switching every
        # later step to slower dynamic-shape kernels
        module.net.compute = torch.compile(module.net.compute, dynamic=False)
    dm = make_datamodule(cfg)
    prepare_data(dm, convert=plan.child_tmp is None)
    if plan.child_tmp is None and (note := few_updates(cfg, len(dm.datasets["train"]))):
        print(f"bsp-train: warning: {note}", file=sys.stderr)
    return module, dm


def _epoch_floor(resume) -> int | None:
    """--epochs below the epochs a resumed run already completed: Lightning refuses to
    restore it (MisconfigurationException); capped there, fit returns at once instead and
    the run ends with the epochs it has (lifecycle.epochs_note)."""
    saved = resume.get("epoch") if resume is not None else None
    return saved if isinstance(saved, int) else None


def _execute(plan: RunPlan, sig) -> TrainResult | None:
    """Model, data and precision (decided once, here, and recorded in config.yaml), then
    the fit and test of a secondary DDP process (None) or of the first one (its result)."""
    module, dm = _model_and_data(plan)
    precision, why = _precision(plan.cfg, module, dm, plan.resume)
    check_precision(precision, plan.cfg["accelerator"])
    saved = _epoch_floor(plan.resume)
    floor = saved if saved is not None and saved > plan.cfg["epochs"] else None
    if plan.child_tmp is None:
        return _first_process(plan, sig, module, dm, (precision, why), floor)
    from .lifecycle import Lifecycle, test_checkpoint

    tmp = plan.child_tmp
    life = Lifecycle(tmp, C.parse_duration(plan.cfg["checkpoint_every"]), sig)
    trainer = make_trainer(plan.cfg, tmp, precision, callbacks=[life], max_epochs=floor)
    ckpt_path = plan.resume["ckpt"] if plan.resume is not None else None
    if plan.resume is not None and plan.resume["run_dir"] is not None:
        ckpt_path = tmp / "checkpoints" / "last.ckpt"
    trainer.fit(module, datamodule=dm, ckpt_path=ckpt_path)
    test_checkpoint(trainer, module, dm, tmp)  # the same checkpoint as the first process
    return None


def _first_process(plan: RunPlan, sig, module, dm, precision: tuple, floor):
    """The first process: the run directory, written under a temporary name and published
    when complete; an interrupted or failed run is left incomplete, to be resumed."""
    cfg, resume = plan.cfg, plan.resume
    final = Path(cfg["out"])
    copy_from = resume["run_dir"] if resume is not None else None
    refuse_unsafe_output(final, force=cfg["force"], inputs=_inputs(plan),
                         in_place=copy_from)  # again: the output may have appeared meanwhile
    run = RunDirectory(final, force=cfg["force"], copy_from=copy_from, tmp_name=plan.shared)
    with run as tmp:
        previous = read_marker(tmp)  # an incomplete run being continued
        life_marker = {"out": str(final.absolute()), "pid": os.getpid()}
        write_marker(tmp, **life_marker, state="running", epoch=None, step=None,
                     **({"fit_done": previous["fit_done"]}
                        if previous and previous.get("fit_done") else {}))
        # now: an interrupted run can be resumed
        _write_config(cfg, tmp, precision[0], precision_reason=precision[1])
        ckpt_path = tmp / "checkpoints" / "last.ckpt" if copy_from is not None else (
            resume["ckpt"] if resume is not None else None)
        job = _Job(plan, sig, module, dm, tmp, final, precision, life_marker, previous)
        return job.fit_and_test(run, ckpt_path, floor, copy_from)


@dataclass
class _Job:
    """The first process's fit, test and collection in its temporary run directory."""
    plan: RunPlan
    sig: object  # the signals' state (stopping.signals)
    module: object
    dm: object
    tmp: Path
    final: Path
    precision: tuple  # (precision, why), as config.yaml records it
    life_marker: dict
    previous: dict | None  # the marker of an incomplete run being continued

    def fit_and_test(self, run, ckpt_path, floor, copy_from) -> TrainResult:
        import lightning.pytorch as pl

        from .initial import log_initial
        from .lifecycle import Lifecycle
        from .stopping import Interrupted, OutputWriteError

        cfg, t_start = self.plan.cfg, time.time()
        life = Lifecycle(self.tmp, C.parse_duration(cfg["checkpoint_every"]), self.sig,
                         self.life_marker)
        # a run stopped after its training ended (while testing or writing metrics): its
        # last epoch again as the cap, so fit restores the callbacks and returns
        done = self.previous.get("fit_done") if self.previous else None
        trainer = make_trainer(cfg, self.tmp, self.precision[0], callbacks=[life],
                               max_epochs=done or floor)
        self._announce(trainer)
        t0 = time.perf_counter()
        finished = read_run(copy_from)["metrics"] if copy_from is not None else None
        initial = finished["initial"] if finished and finished.get("initial") else \
            _initial(cfg, self.dm, self.module.net)
        seconds = {"initial": time.perf_counter() - t0}
        log_initial(trainer, initial, cfg["quiet"])
        pl.seed_everything(cfg["seed"], workers=True, verbose=False)
        try:
            with _handed_to_ddp_processes(self.tmp):
                return self._fit(trainer, life, ckpt_path, done, initial, seconds)
        except (Interrupted, OutputWriteError) as exc:
            self._leave_incomplete(run, exc, t_start)
            raise

    def _announce(self, trainer) -> None:
        cfg = self.plan.cfg
        if cfg["quiet"]:
            return
        n = {s: len(d) for s, d in self.dm.datasets.items()}
        device = trainer.accelerator.__class__.__name__.replace("Accelerator", "").lower()
        print(f"bsp-train: {cfg['task']} / {cfg['model']}, {device} x {trainer.world_size}, "
              f"precision {self.precision[0]}; {n.get('train')} train, {n.get('val')} val, "
              f"{n.get('test')} test clips of {self.dm.h5_path} -> {self.final}")

    def _fit(self, trainer, life, ckpt_path, done, initial, seconds) -> TrainResult:
        from .lifecycle import epochs_note, test_checkpoint
        from .stopping import Interrupted

        life.start_clock()
        load = os.getloadavg()[0]
        trainer.fit(self.module, datamodule=self.dm, ckpt_path=ckpt_path, weights_only=True)
        if self.sig.received is not None:  # during the last validation: stop before testing
            raise Interrupted(self.sig.received)
        # wall and CPU (this process's threads), over every process of a resumed run
        seconds["fit"], seconds["fit_cpu"] = life.fit_seconds()
        # the machine's 1-min load average at fit start and end (this process's last fit):
        # what the wall seconds were measured under
        seconds["load"] = [round(load, 2), round(os.getloadavg()[0], 2)]
        seconds.update({"partial": True} if life.partial else {"carried": True})
        write_marker(self.tmp, **self.life_marker, state="running",
                     fit_done=trainer.current_epoch, epoch=trainer.current_epoch,
                     step=trainer.global_step)
        cfg = epochs_note(self.plan.cfg, trainer, trained=life.trained or bool(done))
        t0 = time.perf_counter()
        tested = test_checkpoint(trainer, self.module, self.dm, self.tmp)
        seconds["test"] = time.perf_counter() - t0
        if tested == "last":
            print("bsp-train: note: no validation ran in this run (it ended before its "
                  "first epoch's validation), so there is no best checkpoint: validated "
                  "and tested the last one (checkpoints/last.ckpt, also saved as best.ckpt)",
                  file=sys.stderr)
        return _finish(cfg, self.tmp, self.final, trainer, initial, self.precision[0],
                       seconds, tested, precision_reason=self.precision[1])

    def _leave_incomplete(self, run, exc, t_start: float) -> None:
        """Something to continue from (a last.ckpt of this process): the run stays as an
        incomplete run directory, its marker saying why; main() says where."""
        from .stopping import Interrupted

        last = self.tmp / "checkpoints" / "last.ckpt"
        if last.is_file() and last.stat().st_mtime >= t_start:
            run.keep_incomplete = True
            marker = read_marker(self.tmp) or {}
            marker.update(self.life_marker, state="interrupted" if isinstance(
                exc, Interrupted) else "failed", reason=str(exc))
            marker.pop("updated", None)
            write_marker(self.tmp, **marker)
        exc.run = run


@contextlib.contextmanager
def _handed_to_ddp_processes(tmp: Path):
    """Lightning starts its DDP processes by running this command again, so the
    environment is the one channel to them: the temporary run directory is handed over
    there while fit and test run (plan_run reads it)."""
    os.environ[ENV_TMP] = str(tmp)
    try:
        yield
    finally:
        os.environ.pop(ENV_TMP, None)


def _precision(cfg: dict, module, dm, resume=None) -> tuple:
    """``(precision, why)`` of the run: ``--precision`` as given, a resumed run's ``auto``
    as it started (.precision.kept_precision), or ``auto`` decided on this machine (a CPU
    with native bf16 or a GPU: a short probe of this model on one of its train batches,
    cached per model, CPU or GPU and thread count; .precision)."""
    import torch

    if cfg["precision"] == "auto" and (resume or {}).get("precision"):
        return resume["precision"]
    ds = dm.datasets["train"]
    n = min(cfg["batch_size"], len(ds))
    steps = []  # the batch is read only when a probe runs (auto, native bf16, not cached)
    device = "cuda" if cfg["accelerator"] != "cpu" and torch.cuda.is_available() else "cpu"

    def probe(bf16: bool) -> float:
        if not steps:
            steps.append(time_steps(module.net, ds[list(range(n))], device=device))
        return steps[0](bf16)

    key = run_model_key(cfg, module.hparams["hparams"], n, module.net.speed_revision)
    return decide_precision(cfg["precision"], cfg["accelerator"], module.net, probe=probe,
                            key=probe_key(key, torch.get_num_threads(), device))


def _inputs(plan: RunPlan) -> list:
    """What a run reads and ``--out`` must never replace: the data (folder, data.csv or
    HDF5 file), a mix's clip files, the --config file and the checkpoint it starts from."""
    cfg, resume = plan.cfg, plan.resume
    return [cfg.get("data"), *(cfg.get("mix_data") or {}).values(), plan.config_path,
            resume["ckpt"] if resume is not None and resume["run_dir"] is None else None]


def _initial(cfg: dict, dm, model=None) -> dict:
    from .initial import initial_metrics

    loaders = {"val": dm.val_dataloader(), "test": dm.test_dataloader()}
    return initial_metrics(cfg["task"], dm.train_dataloader(), loaders,
                           limit=cfg["limit_batches"], model=model, per_recording=True)


def _finish(cfg, tmp: Path, final: Path, trainer, initial, precision, seconds,
            tested: str = "best", precision_reason: str | None = None):
    from ..reporting.curves import plot_curves
    from .logs import read_logs
    from .stopping import OutputWriteError

    test = dict(trainer.lightning_module.results.get("test", {}))
    from .per_recording import write_breakdown

    initial = dict(initial)  # the per-recording sums go to their own file, not metrics.json
    write_breakdown(tmp, cfg["task"], trainer.lightning_module.results.get("test_per_recording"),
                    initial.pop("test_per_recording", None))
    best_epoch = _best_epoch(trainer)  # 1-based
    logs = read_logs(tmp)  # the best epoch's other val metrics, as logged
    val = {k.split("/", 1)[1]: s[best_epoch - 1] for k, s in logs.items()
           if k.startswith("val/") and best_epoch - 1 in s} if best_epoch is not None else {}
    if tested == "last":  # no epoch was validated: the tested checkpoint's val metrics
        val = {k: float(v) for k, v in trainer.lightning_module.results.get("val", {}).items()}
    epochs = int(trainer.current_epoch)
    module = trainer.lightning_module
    units = get_task(cfg["task"]).units
    metrics = {"task": cfg["task"], "model": cfg["model"],
               "hparams": module.hparams["hparams"], "test": test, "val": val,
               "initial": initial, "best_epoch": best_epoch,
               "epochs": epochs, "best_checkpoint": "checkpoints/best.ckpt", "tested": tested,
               "units": {k: units[k] for k in test if k in units}, "precision": precision,
               "world_size": int(trainer.world_size), "seconds": seconds}
    try:
        if tested == "last":  # the checkpoint the metrics are of, where bsp-eval looks
            with atomic_output(tmp / "checkpoints" / "best.ckpt", force=True) as part:
                shutil.copyfile(tmp / "checkpoints" / "last.ckpt", part)  # not via memory
        write_json(metrics, tmp / "metrics.json")
        _write_config(cfg, tmp, precision, h5=trainer.datamodule.h5_path,
                      hparams=metrics["hparams"], world_size=metrics["world_size"],
                      precision_reason=precision_reason)
        plot_curves(logs, get_task(cfg["task"]).curve_metrics, tmp / "curves.png",
                    initial=initial.get("val"), title=f"{cfg['task']} / {cfg['model']}",
                    best_epoch=best_epoch)
        remove(tmp / MARKER)  # the run is complete
    except OSError as exc:
        remove(tmp / "metrics.json")  # no metrics.json: nothing takes it for finished
        raise OutputWriteError(exc.errno, f"{getattr(exc, 'filename', None) or tmp}: "
                               f"cannot write the run's results ({exc.strerror or exc}); "
                               "the checkpoints are intact") from None
    return TrainResult(run_dir=final, metrics=test, val=val, initial=initial,
                       best_checkpoint=final / "checkpoints" / "best.ckpt",
                       last_checkpoint=final / "checkpoints" / "last.ckpt",
                       best_epoch=metrics["best_epoch"], epochs=epochs, config=cfg,
                       seconds=seconds)


def _write_config(cfg: dict, tmp: Path, precision: str, **resolved) -> None:
    """config.yaml (usable as --config): the options as given, and under ``resolved`` what
    the run resolved, the data and run directory as absolute paths included (so --resume
    works from any directory); its versions and the machine that finished it."""
    import lightning
    import torch

    from .._version import __version__
    extra = {"resolved": {"precision": precision,
                          "data": str(Path(cfg["data"]).absolute()),
                          "out": str(Path(cfg["out"]).absolute()),
                          **{k: (str(Path(v).absolute()) if k == "h5" else v)
                             for k, v in resolved.items()}},
             "versions": {"bsp_fast": __version__, "torch": str(torch.__version__),
                          "lightning": str(lightning.__version__)},
             "machine": machine_record(cfg["accelerator"])}
    # force/resume are actions of this command, not settings of the run
    C.write_yaml(dict(cfg, force=False, resume=None), tmp / "config.yaml", extra)


def _best_epoch(trainer) -> int | None:
    """1-based epoch of ``ModelCheckpoint``'s best checkpoint (None: none validated)."""
    best = trainer.checkpoint_callback
    if not best.best_model_path or best.best_model_score is None:
        return None
    from .checkpoint_file import checkpoint_info
    return int(checkpoint_info(best.best_model_path)["epoch"]) + 1


def train(task: str | None = None, model: str | None = None, data=None, out=None, *,
          config=None, **options) -> TrainResult:
    """Trains ``model`` on ``task`` with the data at ``data`` (dataset directory or HDF5
    file) and writes the run directory ``out``. ``options`` are those of ``bsp-train``
    with underscores (``epochs=2, batch_size=64, hp={"hidden": 32}, noise=5.0``);
    ``config`` a YAML file of options. Raises ``ValueError`` for bad options,
    :class:`~bsp_fast.training.runs.RunError` for unusable data or run directories."""
    given = {k: v for k, v in dict(task=task, model=model, data=data, out=out).items()
             if v is not None}
    given.update(options)
    result = _train(C.normalise(given), config)
    if result is None:
        raise RuntimeError("train() ran as a secondary DDP process")
    return result


# ---------------------------------------------------------------------- CLI
def _epilog() -> str:
    from ..models.catalogue import catalogue

    lines = ["tasks and models:"]
    for task in TASKS:
        lines.append(f"  {task}:")
        for name, entry in catalogue()[task].items():
            lines.append(f"    {name:24s} {entry.description}")
    lines += ["", "exit codes: 0 success, 1 bad data or failure, 2 bad arguments, 3 run "
              "directory exists (use --force), 130 interrupted",
              "docs: docs/training.md"]
    return "\n".join(lines)


def build_parser():
    """bsp-train's jsonargparse parser (``config.parser``)."""
    return C.parser(
        prog="bsp-train",
        description="Train a baseline of the CARLA-BSP report on one task, test its best "
                    "checkpoint (lowest val loss) and write a run directory: config.yaml, "
                    "metrics.json, curves.png, checkpoints/, logs/.",
        epilog=_epilog())


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    return run_command("bsp-train", _main, argv)


def _main(argv) -> int:
    parser = build_parser()  # an ImportError names the 'torch' extra (jsonargparse)
    try:
        cli, config_path, print_config = C.parse_command_line(parser, argv)
    except argparse.ArgumentError as exc:  # one line, as every command's (command_line)
        raise C.ConfigError(f"error: {exc}{error_hint(str(exc), parser)} (see bsp-train "
                            "--help)") from None
    if print_config:
        print(C.dump(resolve_config(cli, config_path)[0]), end="")
        return 0
    try:
        result = _train(cli, config_path)
    except KeyboardInterrupt:
        print("bsp-train: interrupted; nothing written", file=sys.stderr)
        return 130
    except BaseException as exc:  # SIGINT/SIGTERM (Interrupted) or a full disk
        return _stopped(exc)
    if result is None:  # a DDP process started by Lightning
        return 0
    from ..reporting.run_tables import runs_table  # printed with --quiet too: the result
    from .runs import read_finished
    from .tasks import TABLE_COLUMNS

    print(runs_table(read_finished([result.run_dir]), TABLE_COLUMNS))
    print(f"wrote {result.run_dir}")
    return 0


def _stopped(exc: BaseException) -> int:
    """A run stopped by a signal or a full disk: where it was left and how to continue it;
    other errors go on to the commands' one ladder (command_line.exit_code)."""
    from .stopping import Interrupted, OutputWriteError

    if not isinstance(exc, (Interrupted, OutputWriteError)):
        raise exc
    left = getattr(getattr(exc, "run", None), "left_in", None)
    if isinstance(exc, Interrupted):
        where = f" at {resume_hint(left)}" if left else "; nothing written"
        print(f"bsp-train: interrupted ({exc}){where}", file=sys.stderr)
        return exc.code
    where = f"; the run is left at {resume_hint(left)}" if left else "; nothing written"
    print(f"bsp-train: {exc.strerror}{where}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
