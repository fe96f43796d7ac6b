"""``bsp-train TASK MODEL --data DATASET``: train a baseline, test it, write a run directory.

Python: ``bsp_fast.train("lifting", "martinez", data="clips.h5", epochs=30)`` returns a
:class:`TrainResult`. See docs/training.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from . import config as C
from .config import resolve_config  # defaults < resumed run < --config < options
from .runs import ENV_TMP, RunDirectory, RunError, read_run, refuse_unsafe_output, \
    write_json
from .precision import check_precision, native_bf16, resolve_precision
from .tasks import TASKS, get_task

# (resolve_precision, native_bf16 and check_precision live in .precision; importable here too)
__all__ = ["train", "main", "TrainResult", "resolve_precision", "native_bf16", "check_precision"]


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


def _rank() -> int:  # Lightning's: from the launcher's environment, then the trainer's
    from lightning.pytorch.utilities import rank_zero_only

    return rank_zero_only.rank


# ---------------------------------------------------------------------- data
def make_datamodule(cfg: dict, h5=None):
    """The ``BSPDataModule`` of a config (``h5``: an existing file to use instead)."""
    from ..data import BSPDataModule

    data = Path(h5 or cfg["data"])
    if not data.exists():
        raise RunError(f"{data}: no such dataset directory or HDF5 file")
    # strings, not Paths: the data module's arguments are saved in checkpoints, which are
    # read back with torch.load(weights_only=True)
    if data.is_dir() or data.name == "data.csv":
        paths = dict(dataset_dir=str(data if data.is_dir() else data.parent))
    else:
        paths = dict(h5_path=str(data))
    convert = dict(label=cfg["label"], crop_size=cfg["crop_size"], seed=cfg["split_seed"])
    for key in ("fov", "eval_clip_offset"):
        if cfg[key] is not None:
            convert[key] = cfg[key]
    task = get_task(cfg["task"])
    dataset_options = task.dataset_options(cfg)
    augment = cfg["augment"] and task.augments
    return BSPDataModule(**paths, task=cfg["task"], clip_length=cfg["clip_length"],
                         clip_offset=cfg["clip_offset"], benchmark=cfg["benchmark"],
                         balance=cfg["balance"], noise=cfg["noise"], mjp=cfg["mjp"],
                         batch_size=cfg["batch_size"], num_workers=cfg["workers"],
                         augment=augment, seed=cfg["seed"], sampler_seed=cfg["seed"],
                         convert_options=convert, dataset_options=dataset_options,
                         verbose=not cfg["quiet"] and _rank() == 0)


def prepare_data(dm, stages=("fit", "test"), convert: bool = True) -> None:
    """Converts (when needed) and opens the splits; any problem with the data becomes a
    :class:`RunError` naming the file."""
    try:
        if convert:
            dm.prepare_data()
        for stage in stages:
            dm.setup(stage)
    except (ValueError, OSError, KeyError) as exc:
        raise RunError(f"data: {exc}") from None
    except Exception as exc:  # the C++ converter's typed errors
        if type(exc).__module__.startswith("bsp_fast"):
            raise RunError(f"data: {type(exc).__name__}: {exc}") from None
        raise
    for split, ds in dm.datasets.items():
        if len(ds) == 0:
            raise RunError(f"data: {dm.h5_path}: split {split!r} holds no clips")


# ---------------------------------------------------------------------- trainer
def _extra_logger(kind: str, tmp: Path, name: str):
    import importlib.util

    from .._extras import install_hint

    if kind == "csv":
        return None
    if kind == "tensorboard":
        if not any(importlib.util.find_spec(m) for m in ("tensorboard", "tensorboardX")):
            raise C.ConfigError(install_hint("tensorboard", "--logger tensorboard"))
        from lightning.pytorch.loggers import TensorBoardLogger

        return TensorBoardLogger(save_dir=str(tmp), name="tensorboard", default_hp_metric=False)
    if importlib.util.find_spec("wandb") is None:
        raise C.ConfigError(install_hint("wandb", "--logger wandb"))
    from lightning.pytorch.loggers import WandbLogger

    return WandbLogger(save_dir=str(tmp), name=name, project="bsp_fast", offline=True)


def make_trainer(cfg: dict, tmp: Path | None, precision: str, *, fit: bool = True,
                 callbacks=()):
    """The Lightning Trainer of a run (``tmp``: run directory being written) or, with
    ``fit=False``, an evaluation-only one (no logger, no checkpoints; ``callbacks``)."""
    import warnings

    import lightning.pytorch as pl

    from .checkpointing import RunCheckpoint

    import logging

    warnings.filterwarnings("ignore", message=r".*does not have many workers.*")
    warnings.filterwarnings("ignore", message=r".*number of training batches.*")
    warnings.filterwarnings("ignore", message=r".*isinstance\(treespec, LeafSpec\).*")
    for name in ("lightning.pytorch", "lightning.fabric"):  # device banners and tips
        logging.getLogger(name).setLevel(logging.WARNING)
    from lightning.pytorch.callbacks.progress.progress_bar import ProgressBar

    from .progress import progress_callbacks

    limit = cfg["limit_batches"] or None
    callbacks = list(callbacks)
    given = any(isinstance(c, ProgressBar) for c in callbacks)  # e.g. bsp-predict's
    bars = [] if given else progress_callbacks(cfg["quiet"])  # plain lines in a log file
    callbacks += bars
    common = dict(accelerator=cfg["accelerator"], precision=precision,
                  enable_progress_bar=bool(bars) or given, enable_model_summary=False,
                  deterministic=True, num_sanity_val_steps=0, use_distributed_sampler=False,
                  limit_train_batches=limit, limit_val_batches=limit, limit_test_batches=limit)
    try:
        if not fit:
            return pl.Trainer(devices=1, logger=False, enable_checkpointing=False,
                              callbacks=list(callbacks), **common)
        from lightning.pytorch.loggers import CSVLogger

        loggers = [CSVLogger(save_dir=str(tmp), name="logs")]
        extra = _extra_logger(cfg["logger"], tmp, Path(cfg["out"]).name)
        loggers += [extra] if extra is not None else []
        callbacks += [RunCheckpoint(dirpath=str(tmp / "checkpoints"), filename="best",
                                   monitor="val/loss", mode="min", save_top_k=1,
                                   save_last=True, enable_version_counter=False)]
        if cfg["early_stop"]:
            from lightning.pytorch.callbacks import EarlyStopping

            callbacks.append(EarlyStopping(monitor="val/loss", mode="min",
                                           patience=cfg["early_stop"]))
        return pl.Trainer(devices=cfg["devices"], strategy=cfg["strategy"],
                          num_nodes=cfg.get("num_nodes") or 1,
                          max_epochs=cfg["epochs"], max_steps=cfg.get("max_steps") or -1,
                          logger=loggers, callbacks=callbacks,
                          default_root_dir=str(tmp), log_every_n_steps=50, **common)
    except C.ConfigError:
        raise
    except Exception as exc:  # e.g. --accelerator gpu without a GPU
        raise C.ConfigError(f"cannot set up training ({type(exc).__name__}: {exc})") from None


# ---------------------------------------------------------------------- the run
def _shared_tmp(cfg: dict) -> str | None:
    """Processes the user started (torchrun, or one bsp-train per machine with NODE_RANK
    and --num-nodes): the run directory's temporary name, the same on every rank."""
    if "TORCHELASTIC_RUN_ID" not in os.environ and (cfg.get("num_nodes") or 1) == 1:
        return None
    return f".{Path(cfg['out']).name}.tmp-ddp-{os.environ.get('MASTER_PORT', '0')}"


def _train(cli: dict, config_path=None) -> TrainResult | None:
    cfg, resume = resolve_config(cli, config_path)
    import lightning.pytorch as pl
    import torch

    from .initial import log_initial
    from .tasks import TASK_MODULES

    shared = _shared_tmp(cfg)
    in_place = resume["run_dir"] if resume is not None else None
    if not os.environ.get(ENV_TMP):  # before any work: --force never replaces an input
        refuse_unsafe_output(cfg["out"], force=cfg["force"],
                             inputs=_inputs(cfg, resume, config_path), in_place=in_place)
    started = max(int(os.environ.get(k, "0")) if os.environ.get(k, "").isdigit() else 0
                  for k in ("RANK", "NODE_RANK"))  # > 0: not the first process/machine
    if shared and started > 0 and not os.environ.get(ENV_TMP):
        os.environ[ENV_TMP] = str(Path(cfg["out"]).absolute().with_name(shared))
    # a DDP process Lightning started, or one the user started on another machine
    child = bool(os.environ.get(ENV_TMP)) and max(_rank(), started) > 0
    if cfg["threads"]:
        torch.set_num_threads(cfg["threads"])
    from ..models import model_class

    precision = resolve_precision(cfg["precision"], cfg["accelerator"],
                                  model_class(cfg["task"], cfg["model"]))
    # the model first: a bad --hp is refused before any data is converted (the data setup
    # draws no random number, so the weights are those of the seed either way)
    pl.seed_everything(cfg["seed"], workers=True, verbose=False)
    try:
        module = TASK_MODULES[cfg["task"]](cfg["model"], hparams=cfg["hp"], lr=cfg["lr"],
                                           config=cfg)
    except (ValueError, TypeError, AssertionError, RuntimeError) as exc:
        raise C.ConfigError(f"model {cfg['model']!r}: {exc}") from None
    check_precision(precision, cfg["accelerator"])
    dm = make_datamodule(cfg)
    prepare_data(dm, convert=not child)
    ckpt_path = None
    if resume is not None:
        ckpt_path = resume["ckpt"]
    if child:
        tmp = Path(os.environ[ENV_TMP])
        trainer = make_trainer(cfg, tmp, precision)
        if resume is not None and resume["run_dir"] is not None:
            ckpt_path = tmp / "checkpoints" / "last.ckpt"
        trainer.fit(module, datamodule=dm, ckpt_path=ckpt_path)
        trainer.test(module, datamodule=dm, ckpt_path="best", verbose=False)
        return None
    final = Path(cfg["out"])
    copy_from = resume["run_dir"] if resume is not None else None
    refuse_unsafe_output(final, force=cfg["force"], inputs=_inputs(cfg, resume, config_path),
                         in_place=copy_from)  # again: the output may have appeared meanwhile
    with RunDirectory(final, force=cfg["force"], copy_from=copy_from, tmp_name=shared) as tmp:
        if copy_from is not None:
            ckpt_path = tmp / "checkpoints" / "last.ckpt"
        trainer = make_trainer(cfg, tmp, precision)
        if not cfg["quiet"]:
            n = {s: len(d) for s, d in dm.datasets.items()}
            print(f"bsp-train: {cfg['task']} / {cfg['model']}, {trainer.accelerator.__class__.__name__.replace('Accelerator', '').lower()} "
                  f"x {trainer.world_size}, precision {precision}; {n.get('train')} train, "
                  f"{n.get('val')} val, {n.get('test')} test clips of {dm.h5_path} -> {final}")
        seconds = {}
        t0 = time.perf_counter()
        previous = read_run(copy_from)["metrics"] if copy_from is not None else None
        if previous and previous.get("initial"):
            initial = previous["initial"]
        else:
            initial = _initial(cfg, dm, module.net)
        seconds["initial"] = time.perf_counter() - t0
        log_initial(trainer, initial, cfg["quiet"])
        pl.seed_everything(cfg["seed"], workers=True, verbose=False)
        os.environ[ENV_TMP] = str(tmp)
        try:
            t0 = time.perf_counter()
            trainer.fit(module, datamodule=dm, ckpt_path=ckpt_path)
            seconds["fit"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            trainer.test(module, datamodule=dm, ckpt_path="best", verbose=False)
            seconds["test"] = time.perf_counter() - t0
        finally:
            os.environ.pop(ENV_TMP, None)
        result = _finish(cfg, tmp, final, trainer, initial, precision, seconds)
    return result


def _inputs(cfg: dict, resume, config_path=None) -> list:
    """What a run reads and ``--out`` must never replace: the data (folder, data.csv or
    HDF5 file), the --config file and the checkpoint it starts from."""
    return [cfg.get("data"), config_path,
            resume["ckpt"] if resume is not None and resume["run_dir"] is None else None]


def _initial(cfg: dict, dm, model=None) -> dict:
    from .initial import initial_metrics

    loaders = {"val": dm.val_dataloader(), "test": dm.test_dataloader()}
    return initial_metrics(cfg["task"], dm.train_dataloader(), loaders,
                           limit=cfg["limit_batches"], model=model, per_recording=True)


def _finish(cfg, tmp: Path, final: Path, trainer, initial, precision, seconds):
    from .. import __version__
    from .curves import plot_curves, read_logs

    test = dict(trainer.lightning_module.results.get("test", {}))
    from .breakdown import write_breakdown

    initial = dict(initial)  # the per-recording sums go to their own file, not metrics.json
    write_breakdown(tmp, cfg["task"], trainer.lightning_module.results.get("test_per_recording"),
                    initial.pop("test_per_recording", None))
    best_epoch = _best_epoch(trainer)  # 1-based
    logs = read_logs(tmp)  # the best epoch's other val metrics, as logged
    val = {k.split("/", 1)[1]: s[best_epoch - 1] for k, s in logs.items()
           if k.startswith("val/") and best_epoch - 1 in s} if best_epoch is not None else {}
    epochs = int(trainer.current_epoch)
    module = trainer.lightning_module
    units = get_task(cfg["task"]).units
    metrics = {"task": cfg["task"], "model": cfg["model"],
               "hparams": module.hparams["hparams"], "test": test, "val": val,
               "initial": initial, "best_epoch": best_epoch,
               "epochs": epochs, "best_checkpoint": "checkpoints/best.ckpt",
               "units": {k: units[k] for k in test if k in units}, "precision": precision,
               "world_size": int(trainer.world_size), "seconds": seconds}
    write_json(metrics, tmp / "metrics.json")
    import lightning
    import torch

    extra = {"resolved": {"precision": precision, "h5": str(Path(trainer.datamodule.h5_path).absolute()),
                          "hparams": metrics["hparams"], "world_size": metrics["world_size"]},
             "versions": {"bsp_fast": __version__, "torch": str(torch.__version__),
                          "lightning": str(lightning.__version__)}}
    # force/resume are actions of this command, not settings of the run
    C.write_yaml(dict(cfg, force=False, resume=None), tmp / "config.yaml", extra)
    plot_curves(tmp, cfg["task"], initial=initial.get("val"),
                title=f"{cfg['task']} / {cfg['model']}", best_epoch=best_epoch)
    return TrainResult(run_dir=final, metrics=test, val=val, initial=initial,
                       best_checkpoint=final / "checkpoints" / "best.ckpt",
                       last_checkpoint=final / "checkpoints" / "last.ckpt",
                       best_epoch=metrics["best_epoch"], epochs=epochs, config=cfg,
                       seconds=seconds)


def _best_epoch(trainer) -> int | None:
    """1-based epoch of ``ModelCheckpoint``'s best checkpoint (None: none validated)."""
    from .tasks import checkpoint_info

    best = trainer.checkpoint_callback
    if not best.best_model_path or best.best_model_score is None:
        return None
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
    lines = ["tasks and models:"]
    try:
        from .. import models

        for task in TASKS:
            lines.append(f"  {task}:")
            for name, text in models.available(task).items():
                lines.append(f"    {name:24s} {text}")
    except Exception as exc:  # pragma: no cover - models not importable
        lines.append(f"  (model list unavailable: {exc})")
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
    try:
        parser = build_parser()
    except ImportError as exc:  # jsonargparse, of the 'torch' extra
        print(f"bsp-train: {exc}", file=sys.stderr)
        return 1
    try:
        cli, config_path, print_config = C.parse_command_line(parser, argv)
        if print_config:
            print(C.dump(resolve_config(cli, config_path)[0]), end="")
            return 0
        result = _train(cli, config_path)
    except argparse.ArgumentError as exc:  # argparse's form: usage, then the message
        parser.print_usage(sys.stderr)
        print(f"bsp-train: error: {exc}", file=sys.stderr)
        return 2
    except C.ConfigError as exc:
        print(f"bsp-train: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"bsp-train: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print("bsp-train: interrupted; nothing written", file=sys.stderr)
        return 130
    if result is None:  # a DDP process started by Lightning
        return 0
    from .tables import runs_table  # printed with --quiet too: the result of the command

    print(runs_table([result.run_dir]))
    print(f"wrote {result.run_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
