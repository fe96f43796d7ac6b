"""Scoring and predicting a saved checkpoint with plain PyTorch (``bsp-eval``,
``bsp-predict``): the checkpoint's net, the run's data and precision, and the very steps
the LightningModule's test and predict steps run (:func:`.scoring.eval_step`,
:func:`.scoring.prediction_step`), without Lightning's Trainer, whose import alone costs
seconds. The numbers equal ``Trainer.test``'s to the last digit
(tests/python/test_scorer.py): the same inference mode, autocast and batches.
"""
from __future__ import annotations

import contextlib
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .checkpoint_file import read_checkpoint
from .per_recording import RecordingBreakdown, recording_ids
from .scoring import TaskMetrics, eval_step, prediction_step
from .tasks import get_task

__all__ = ["SavedModel", "load_saved", "device_of", "score", "predict_batches"]

#: Lightning's precision plugins, as dtypes: autocast (mixed) or the whole net (true)
_AUTOCAST = {"bf16-mixed": "bfloat16", "16-mixed": "float16"}
_TRUE = {"64": "float64", "64-true": "float64", "bf16-true": "bfloat16",
         "16-true": "float16"}


@dataclass
class SavedModel:
    """A checkpoint's net, in eval mode, with what scoring it needs."""
    path: Path
    task: str
    model: str
    hparams: dict  # the saved ones: task, model, hparams, lr, config
    net: object
    spec: object

    def scored_frames(self, L: int) -> slice:
        """The frames of an ``L``-frame clip that are scored and predicted."""
        return self.spec.scored_frames(self.net, L)


def load_saved(ckpt_path) -> SavedModel:
    """The net of a bsp-train checkpoint, rebuilt from its saved hyper-parameters and
    weights (``weights_only``: a checkpoint is untrusted input)."""
    from .. import models

    ckpt = read_checkpoint(ckpt_path)
    hp = dict(ckpt["hyper_parameters"])
    net = models.create(hp["task"], hp["model"], **dict(hp.get("hparams") or {}))
    weights = {k[len("net."):]: v for k, v in (ckpt.get("state_dict") or {}).items()
               if k.startswith("net.")}
    try:
        net.load_state_dict(weights)
    except RuntimeError as exc:
        raise ValueError(f"{ckpt_path}: its weights do not fit model {hp['model']!r} "
                         f"({str(exc).splitlines()[0]})") from None
    net.eval()
    return SavedModel(Path(ckpt_path), hp["task"], hp["model"], hp, net, get_task(hp["task"]))


def device_of(accelerator: str):
    """Where Lightning would run: a GPU for ``gpu``, and for ``auto`` when one exists."""
    import torch

    cuda = accelerator in ("gpu", "auto") and torch.cuda.is_available()
    return torch.device("cuda" if cuda else "cpu")


def _to(batch, device, dtype=None):
    """The batch's tensors on ``device`` (and its floating ones in ``dtype``), as
    Lightning's batch transfer and its true-precision plugins move them."""
    import torch

    if isinstance(batch, dict):
        return {k: _to(v, device, dtype) for k, v in batch.items()}
    if isinstance(batch, (list, tuple)):
        return type(batch)(_to(v, device, dtype) for v in batch)
    if torch.is_tensor(batch):
        if dtype is not None and batch.is_floating_point():
            batch = batch.to(dtype)
        return batch if batch.device == device else batch.to(device)
    return batch


@contextlib.contextmanager
def _precision(saved: SavedModel, precision: str, device):
    """The forward context of Lightning's plugin for ``precision``; yields the dtype the
    batch's floating tensors are converted to (None: as loaded)."""
    import torch

    if precision in _AUTOCAST:
        with torch.autocast(device.type, dtype=getattr(torch, _AUTOCAST[precision])):
            yield None
    elif precision in _TRUE:
        dtype, before = getattr(torch, _TRUE[precision]), torch.get_default_dtype()
        saved.net.to(dtype)
        torch.set_default_dtype(dtype)
        try:
            yield dtype
        finally:
            torch.set_default_dtype(before)
    else:  # 32 / 32-true
        yield None


def _batches(loader, limit: int, desc: str, progress: bool):
    """The loader's first ``limit`` batches (0: all): with ``progress``, a bar on a
    terminal, else (a log file, a pipe) a plain line every few seconds and one at the end,
    ``[  1.2 s] predicting done: 3 batch(es)``."""
    import itertools

    batches = itertools.islice(loader, limit or None)
    if not progress:
        return batches
    total = min(len(loader), limit) if limit else len(loader)
    if sys.stderr.isatty():
        from tqdm import tqdm

        return tqdm(batches, total=total, desc=desc, file=sys.stderr, leave=False)
    return _plain_lines(batches, desc, total)


def _plain_lines(batches, desc: str, total: int):
    from .._plain_progress import INTERVAL, stamp

    t0 = last = time.perf_counter()
    done = 0
    for batch in batches:
        yield batch
        done += 1
        if time.perf_counter() - last >= INTERVAL:
            last = time.perf_counter()
            print(stamp(t0, f"{desc}, batch {done}/{total}"), file=sys.stderr, flush=True)
    print(stamp(t0, f"{desc} done: {done} batch(es)"), file=sys.stderr, flush=True)


def score(saved: SavedModel, loader, precision: str, device, *, per_recording: bool = True,
          observers=(), limit: int = 0, progress: bool = False) -> dict:
    """Scores every batch of ``loader`` (the first ``limit``): ``{"metrics",
    "per_recording", "clips", "recordings"}``. ``observers``: objects whose
    ``update(spec, net, output, batch)`` sees every scored batch (e.g. the breakdown's
    collector) and whose ``start(spec, net)``, where they have one, runs before the first
    (e.g. a decoding to score the net with)."""
    import torch

    for observer in observers:
        if callable(getattr(observer, "start", None)):
            observer.start(saved.spec, saved.net)
    saved.net.to(device)
    metrics = TaskMetrics(saved.task).to(device)
    recordings = RecordingBreakdown(saved.task) if per_recording else None
    clips, seen = 0, set()
    with torch.inference_mode(), _precision(saved, precision, device) as dtype:
        for batch in _batches(loader, limit, "scoring", progress):
            batch = _to(batch, device, dtype)
            output = eval_step(saved.spec, saved.net, batch, metrics)
            if recordings is not None:
                recordings.update(output.detach().float(), batch, saved.net)
            for observer in observers:
                observer.update(saved.spec, saved.net, output.detach(), batch)
            clips += len(batch["meta"]["index"])
            seen.update(recording_ids(batch["meta"]))
    return {"metrics": metrics.compute(), "clips": clips, "recordings": len(seen),
            "per_recording": recordings.compute() if recordings is not None else None}


def predict_batches(saved: SavedModel, loader, precision: str, device, *, limit: int = 0,
                    progress: bool = False):
    """Yields :func:`.scoring.prediction_step`'s outputs for every batch of ``loader``."""
    import torch

    saved.net.to(device)
    with torch.inference_mode(), _precision(saved, precision, device) as dtype:
        for batch in _batches(loader, limit, "predicting", progress):
            yield prediction_step(saved.spec, saved.net, _to(batch, device, dtype))
