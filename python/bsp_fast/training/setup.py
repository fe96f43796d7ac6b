"""What a run is built from: its DataModule and its Lightning Trainer (``bsp-train``,
``bsp-eval``, ``bsp-predict`` and ``bsp-reproduce`` share them)."""
from __future__ import annotations

from pathlib import Path

from . import config as C
from .runs import RunError
from .tasks import get_task

__all__ = ["make_datamodule", "prepare_data", "make_trainer", "rank"]


def rank() -> int:  # Lightning's: from the launcher's environment, then the trainer's
    from lightning.pytorch.utilities import rank_zero_only

    return rank_zero_only.rank


# ---------------------------------------------------------------------- data
def make_datamodule(cfg: dict, h5=None, *, plain: bool = False):
    """The ``BSPDataModule`` of a config (``h5``: an existing file to use instead), or with
    ``mix`` a ``MixedDataModule`` (its ``data: true`` source reads that data module).
    ``plain``: the same data as a ``ClipData``, without Lightning (scoring a checkpoint)."""
    if cfg.get("mix") is not None:
        return _mixed_datamodule(cfg, h5)
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
    if plain:
        from ..data.clip_data import ClipData as cls
    else:
        from ..data.datamodule import BSPDataModule as cls
    return cls(**paths, task=cfg["task"], clip_length=cfg["clip_length"],
               clip_offset=cfg["clip_offset"], benchmark=cfg["benchmark"],
               balance=cfg["balance"], noise=cfg["noise"], mjp=cfg["mjp"],
               batch_size=cfg["batch_size"], num_workers=cfg["workers"],
               augment=augment, seed=cfg["seed"], sampler_seed=cfg["seed"],
               convert_options=convert, dataset_options=dataset_options,
               test_dir=cfg.get("test_data"),
               verbose=not cfg["quiet"] and (plain or rank() == 0))


def _mixed_datamodule(cfg: dict, h5=None):
    """A mixed run's data (docs/interop.md, Mixed training): the mix's sources in their
    shares, tested on ``test_on`` alone when given; the source marked ``data: true``
    reads ``--data`` converted as a one-file run converts it, at the mix's clip length."""
    from ..data.mix_tables import plan_mix
    from ..data.mixed import MixedDataModule

    mix = cfg["mix"]
    try:
        plan = plan_mix(mix, cfg.get("mix_data") or {}, cfg["data"], cfg.get("test_on"))
        base = None
        if any(s["data"] for s in plan["sources"] + [plan["test"] or {}]):
            L = cfg["clip_length"] or mix.get("clip_length")
            base = make_datamodule(dict(cfg, mix=None, clip_length=L), h5)
        task = get_task(cfg["task"])
        return MixedDataModule(
            plan["sources"], cfg["task"], cfg["batch_size"], cfg["workers"],
            epoch_size=mix.get("epoch_size"), seed=cfg["seed"], noise=cfg["noise"],
            mjp=cfg["mjp"], augment=cfg["augment"] and task.augments,
            dataset_options=task.dataset_options(cfg), test_source=plan["test"], base=base,
            clip_length=mix.get("clip_length"))
    except ValueError as exc:
        raise RunError(f"data: {exc}") from None


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


def _quiet_lightning() -> None:
    """Silences Lightning's warnings that do not apply to these runs, and its banners."""
    import logging
    import warnings

    warnings.filterwarnings("ignore", message=r".*does not have many workers.*")
    warnings.filterwarnings("ignore", message=r".*number of training batches.*")
    warnings.filterwarnings("ignore", message=r".*isinstance\(treespec, LeafSpec\).*")
    # a resumed run's copied checkpoints/ (the callbacks' saved state knows them)
    warnings.filterwarnings("ignore", message=r".*Checkpoint directory .* exists and is not empty.*")
    # resuming mid-epoch: Lifecycle makes our sampler skip the batches already trained on
    warnings.filterwarnings("ignore", message=r".*resuming from a checkpoint that ended before "
                            r"the epoch ended.*")
    # TaskModule.transfer_batch_to_device (no walk over CPU batches) is meant to win
    warnings.filterwarnings("ignore", message=r".*overridden `transfer_batch_to_device`.*")
    # an epoch without validation (--max-steps within the first epoch): bsp-train says so
    warnings.filterwarnings("ignore", message=r".*could not find the monitored key.*")
    for name in ("lightning.pytorch", "lightning.fabric"):  # device banners and tips
        logging.getLogger(name).setLevel(logging.WARNING)


def _fit_loggers(cfg: dict, tmp: Path) -> list:
    """The CSV log under ``tmp``, and the config's extra logger if any."""
    from lightning.pytorch.loggers import CSVLogger

    loggers = [CSVLogger(save_dir=str(tmp), name="logs")]
    extra = _extra_logger(cfg["logger"], tmp, Path(cfg["out"]).name)
    return loggers + ([extra] if extra is not None else [])


def _fit_callbacks(cfg: dict, tmp: Path) -> list:
    """The best checkpoint by validation loss, and early stopping if the config asks."""
    from .checkpointing import RunCheckpoint

    callbacks = [RunCheckpoint(dirpath=str(tmp / "checkpoints"), filename="best",
                               monitor="val/loss", mode="min", save_top_k=1,
                               save_last=False, enable_version_counter=False)]
    if cfg["early_stop"]:
        from lightning.pytorch.callbacks import EarlyStopping

        callbacks.append(EarlyStopping(monitor="val/loss", mode="min",
                                       patience=cfg["early_stop"]))
    return callbacks


def make_trainer(cfg: dict, tmp: Path | None, precision: str, *, fit: bool = True,
                 callbacks=(), max_epochs: int | None = None):
    """The Lightning Trainer of a run (``tmp``: run directory being written) or, with
    ``fit=False``, an evaluation-only one (no logger, no checkpoints). ``callbacks``: more
    callbacks; ``max_epochs``: instead of the config's (a run whose training had ended)."""
    import lightning.pytorch as pl

    _quiet_lightning()  # before the imports below, which warn too
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
        loggers = _fit_loggers(cfg, tmp)
        callbacks += _fit_callbacks(cfg, tmp)
        from .lifecycle import AtomicCheckpointIO

        # a mix's batch sampler is not distributed: one process (config refuses more)
        devices = 1 if cfg.get("mix") is not None and cfg["devices"] == "auto" \
            else cfg["devices"]
        return pl.Trainer(devices=devices, strategy=cfg["strategy"],
                          plugins=[AtomicCheckpointIO()],
                          num_nodes=cfg.get("num_nodes") or 1,
                          max_epochs=max_epochs or cfg["epochs"],
                          max_steps=cfg.get("max_steps") or -1,
                          logger=loggers, callbacks=callbacks,
                          default_root_dir=str(tmp), log_every_n_steps=50, **common)
    except C.ConfigError:
        raise
    except Exception as exc:  # e.g. --accelerator gpu without a GPU
        raise C.ConfigError(f"cannot set up training ({type(exc).__name__}: {exc})") from None
