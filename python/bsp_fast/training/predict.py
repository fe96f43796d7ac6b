"""``bsp-predict RUN_OR_CKPT --out preds.h5``: a model's outputs for one split, de-normalised
(pixels or metres), with the clip ids, so predictions can be plotted or chained.

Written datasets (N clips, L' = the frames the model predicts, see ``frame_start``/
``frame_stop`` attributes):

* every task: ``clip_id``, ``row`` (row in the source split), ``start_frame``, ``label``,
  ``frames (N, L')``, ``video_id``, ``pedestrian_id``, ``age``, ``gender`` (strings);
  what each task adds is its task object's ``predictions`` (``bsp_fast.training.tasks``),
  returned by :func:`.scoring.prediction_step` (the LightningModule's ``predict_step``
  too), batch by batch in plain PyTorch (:mod:`.scorer`):
* classification: ``logits``, ``probability`` (of crossing), ``prediction`` (0/1);
* autoencoder: ``pixels (N, L', 26, 2)`` de-normalised with the *input's* hips/neck
  normalisation (no ground truth used), ``pixels_scored`` (with the clean target's, as
  scored), ``normalised`` (raw output), ``input_pixels``
  (the deformed input, missing joints (0, 0)), ``target_pixels`` (clean 2D);
* lifting: ``metres (N, L', 26, 3)`` hips at the origin, scaled by the reference skeleton's
  hips-neck length of the clip's (age, gender); ``metres_aligned`` (hips on the target's
  hips, as scored); ``normalised``; ``target_metres``;
* pose_estimation: ``crop_pixels`` and ``pixels`` (image pixels through ``crop_box``),
  ``target_crop_pixels``, ``visible``.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..command_line import ArgumentParser, HelpFormatter, run_command
from . import config as C
from .overrides import add_overrides, given_overrides
from ..atomic import atomic_output
from .runs import RunError, check_run_outputs, run_inputs

__all__ = ["predict", "main", "PredictResult"]


@dataclass
class PredictResult:
    path: Path
    task: str
    model: str
    split: str
    clips: int
    datasets: list
    recordings: int = 0


def _np(t):
    if isinstance(t, list):
        return t
    return t.detach().float().cpu().numpy() if t.is_floating_point() else t.detach().cpu().numpy()


def _write(out: Path, force: bool, parts: dict, attrs: dict) -> None:
    """Writes the gathered arrays to ``out`` (temporary name, then renamed)."""
    import h5py

    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out, force=force) as tmp, h5py.File(tmp, "w") as f:
        for k, v in parts.items():
            if isinstance(v[0], list):  # per-clip strings
                data = np.array(sum(v, []), dtype=h5py.string_dtype())
            else:
                data = np.concatenate(v)
            f.create_dataset(k, data=data)
        f.attrs.update(attrs)


def _check_out(out: Path, inputs, force: bool) -> Path:
    """Before any work: ``out`` is a file name, none of the inputs predictions are made
    from (through links too), and new unless ``force``."""
    if out.is_dir():
        raise RunError(f"{out} is a folder; the predictions are one HDF5 file (give a "
                       "file name, e.g. predictions.h5)", code=2)
    check_run_outputs(inputs, [("--out", out)])
    if out.exists() and not force:
        raise RunError(f"{out} exists; pass --force to overwrite it", code=3)
    return out


def _attrs(saved, ckpt, source, split: str, L: int) -> dict:
    """The file's attributes: what was predicted, from what, and which frames."""
    sl = saved.scored_frames(L)
    attrs = {"created_by": "bsp-predict", "task": saved.task, "model": saved.model,
             "checkpoint": str(ckpt), "source": str(source), "split": split,
             "frame_start": sl.start or 0, "frame_stop": sl.stop or L, "clip_length": L,
             "hparams_json": json.dumps(saved.hparams["hparams"], default=str)}
    if saved.spec.prediction_units:  # classification's logits have no unit
        attrs["units"] = saved.spec.prediction_units
    return attrs


def predict(run, out, data=None, *, split: str = "test", which: str = "best",
            batch_size: int | None = None, workers: int | None = None,
            accelerator: str | None = None, noise: float | None = None, mjp=None,
            force: bool = False, progress: bool = False, **overrides) -> PredictResult:
    """Writes the predictions of run directory or checkpoint ``run`` for ``split`` of its
    data (or ``data``) to the HDF5 file ``out`` (temporary name, renamed when complete;
    an existing file needs ``force``). The model runs as ``bsp-eval`` scores it (the run's
    accelerator unless given, precision, threads, and the per-clip evaluation noise, which
    no batch size changes), over every clip of the split, so the predictions are the
    outputs that were scored."""
    from .evaluate import SPLIT_STAGES, load_run, prepare_scoring

    if split not in SPLIT_STAGES:
        raise ValueError(f"split must be one of {list(SPLIT_STAGES)}, got {split!r}")
    if accelerator is not None and accelerator not in C.ACCELERATORS:
        raise ValueError(f"accelerator must be one of {list(C.ACCELERATORS)}, got "
                         f"{accelerator!r}")
    out = _check_out(Path(out), run_inputs(run, which, data), force)
    saved, cfg, ckpt, h5 = load_run(run, which, data, batch_size=batch_size,
                                    workers=workers, accelerator=accelerator, noise=noise,
                                    mjp=mjp, **overrides)
    import torch

    from .scorer import device_of, predict_batches
    from .setup import make_datamodule, prepare_data

    if cfg["accelerator"] == "gpu" and not torch.cuda.is_available():
        raise C.ConfigError("--accelerator gpu: no CUDA device available" if accelerator else
                            f"{ckpt}: the run used --accelerator gpu and no CUDA device is "
                            "available here; pass --accelerator cpu")
    precision = prepare_scoring(cfg, saved)
    dm = make_datamodule(cfg, h5, plain=cfg.get("mix") is None)
    # again, with what loading the run resolved (the saved config's data, its HDF5 file)
    check_run_outputs([ckpt, h5, dm.h5_path, cfg.get("data")], [("--out", out)])
    prepare_data(dm, stages=(SPLIT_STAGES[split],))
    loader = dm.test_dataloader() if split == "test" else dm.val_dataloader()
    attrs = _attrs(saved, ckpt, dm.h5_path, split, dm.datasets[split].clip_length)
    parts: dict = {}
    # the precision bsp-eval scores in; the whole split, whatever the run's --limit-batches
    for step in predict_batches(saved, loader, precision, device_of(cfg["accelerator"]),
                                limit=overrides.get("limit_batches") or 0,
                                progress=progress):
        for k, v in step.items():
            parts.setdefault(k, []).append(_np(v))
    _write(out, force, parts, attrs)
    recs = {(v, p) for vs, ps in zip(parts.get("video_id", []), parts.get("pedestrian_id", []))
            for v, p in zip(vs, ps)}
    return PredictResult(path=out, task=saved.task, model=saved.model, split=split,
                         clips=int(sum(len(v) for v in parts["label"])),
                         datasets=sorted(parts), recordings=len(recs))


def main(argv=None) -> int:
    p = ArgumentParser(
        prog="bsp-predict",
        description="Write a bsp-train model's de-normalised outputs (pixels or metres) for "
                    "one split, with clip ids, to an HDF5 file.",
        epilog="exit codes: 0 success, 1 bad data/run/checkpoint, 2 bad arguments (or --out "
               "is one of the inputs, --force or not), 3 output exists (use --force). docs: "
               "docs/training.md",
        formatter_class=HelpFormatter)
    p.add_argument("run", metavar="RUN_OR_CKPT", help="run directory or .ckpt")
    p.add_argument("--out", metavar="PREDS.h5", help="HDF5 file to write (required)")
    p.add_argument("--data", default=None, metavar="DATASET_OR_H5",
                   help="data to predict on (default: the run's)")
    p.add_argument("--split", default="test", choices=("test", "val"),
                   help="split of the data to predict")
    p.add_argument("--which", default="best", choices=("best", "last"),
                   help="checkpoint of a run directory")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--print-config", action="store_true",
                   help="print the run's config with the options given here applied (YAML, "
                        "usable as bsp-train --config) and exit")
    # how the run is scored: bsp-train's own declarations (training/config.py, scoring=True)
    names = add_overrides(p, "scoring")
    args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
    return run_command("bsp-predict", _main, args, names)


def _main(args, names) -> int:
    if args.print_config:
        from .evaluate import run_config

        cfg = run_config(args.run, args.which, args.data, **given_overrides(args, names))[0]
        print(C.dump(cfg), end="")
        return 0
    if args.out is None:
        raise C.ConfigError("--out PREDS.h5 is required (the HDF5 file to write)")
    res = predict(args.run, args.out, args.data, split=args.split, which=args.which,
                  force=args.force, progress=not args.quiet, **given_overrides(args, names))
    if not args.quiet:
        print(f"wrote {res.path}: {res.clips} {res.split} clips of {res.recordings} "
              f"recordings, {res.task}/{res.model} ({', '.join(res.datasets)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
