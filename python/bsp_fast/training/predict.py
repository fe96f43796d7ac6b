"""``bsp-predict RUN_OR_CKPT --out preds.h5``: a model's outputs for one split, de-normalised
(pixels or metres), with the clip ids, so predictions can be plotted or chained.

Written datasets (N clips, L' = the frames the model predicts, see ``frame_start``/
``frame_stop`` attributes):

* every task: ``clip_id``, ``row`` (row in the source split), ``start_frame``, ``label``,
  ``frames (N, L')``, ``video_id``, ``pedestrian_id``, ``age``, ``gender`` (strings);
* classification: ``logits``, ``probability`` (of crossing), ``prediction`` (0/1);
* autoencoder: ``pixels (N, L', 26, 2)`` de-normalised with the *input's* hips/neck
  normalisation (no ground truth used), ``normalised`` (raw output), ``input_pixels``
  (the deformed input, missing joints (0, 0)), ``target_pixels`` (clean 2D);
* lifting: ``metres (N, L', 26, 3)`` hips at the origin, scaled by the reference skeleton's
  hips-neck length of the clip's (age, gender); ``metres_aligned`` (hips on the target's
  hips, as scored); ``normalised``; ``target_metres``;
* pose_estimation: ``crop_pixels`` and ``pixels`` (image pixels through ``crop_box``),
  ``target_crop_pixels``, ``visible``.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import config as C
from ..atomic import atomic_output
from .runs import RunError

__all__ = ["predict", "main", "PredictResult"]


@dataclass
class PredictResult:
    path: Path
    task: str
    model: str
    split: str
    clips: int
    datasets: list


def _np(t):
    return t.detach().float().cpu().numpy() if t.is_floating_point() else t.detach().cpu().numpy()


def _outputs(task: str, out, batch: dict, net) -> dict:
    """The arrays of one batch (see the module docstring)."""
    import torch

    from .scoring import hips_neck_lengths

    out = out.detach().float()
    res = {}
    if task == "classification":
        prob = torch.sigmoid(out) if out.ndim == 1 else torch.softmax(out, -1)[:, 1]
        res.update(logits=_np(out), probability=_np(prob), prediction=_np((prob >= 0.5).to(torch.int8)))
        return res
    L = batch["targets"].shape[1] if "targets" in batch else batch["inputs"].shape[1]
    sl = net.frame_slice(L)
    if task == "autoencoder":
        scale, shift = batch["scale"][:, sl, None, None], batch["shift"][:, sl, None, :]
        vis = batch["visible"][:, sl, :, None]
        tscale = batch["target_scale"][:, sl, None, None]
        tshift = batch["target_shift"][:, sl, None, :]
        res.update(pixels=_np(out * scale + shift), normalised=_np(out),
                   input_pixels=_np(torch.where(vis, batch["inputs"][:, sl] * scale + shift, 0.0)),
                   target_pixels=_np(batch["targets"][:, sl] * tscale + tshift))
    elif task == "lifting":
        from .. import metrics as M

        hn = hips_neck_lengths(batch["meta"], device=out.device)
        gt = batch["targets_m"][:, sl].float()
        res.update(metres=_np(out * hn[:, None, None, None]), normalised=_np(out),
                   metres_aligned=_np(M.denormalise_lifting(out, gt, hn)), target_metres=_np(gt))
    else:  # pose_estimation: crop pixels -> image pixels through each frame's crop box
        box = batch["crop_box"][:, sl].float()
        S = batch["inputs"].shape[-1]
        size = torch.stack([box[..., 2] - box[..., 0], box[..., 3] - box[..., 1]], -1)
        pixels = out * (size / S)[..., None, :] + box[..., None, :2]
        res.update(crop_pixels=_np(out), pixels=_np(pixels),
                   target_crop_pixels=_np(batch["targets"][:, sl]),
                   visible=_np(batch["visible"][:, sl]))
    res["frames"] = _np(batch["meta"]["frames"][:, sl])
    return res


def predict(run, out, data=None, *, split: str = "test", which: str = "best",
            batch_size: int | None = None, workers: int | None = None,
            accelerator: str = "auto", noise: float | None = None, mjp=None,
            force: bool = False, progress: bool = False) -> PredictResult:
    """Writes the predictions of run directory or checkpoint ``run`` for ``split`` of its
    data (or ``data``) to the HDF5 file ``out`` (temporary name, renamed when complete;
    an existing file needs ``force``)."""
    import h5py
    import torch

    from .evaluate import SPLIT_STAGES, load_run
    from .train import make_datamodule, prepare_data

    if split not in SPLIT_STAGES:
        raise ValueError(f"split must be one of {list(SPLIT_STAGES)}, got {split!r}")
    out = Path(out)
    if out.exists() and not force:
        raise RunError(f"{out} exists; pass --force to overwrite it", code=3)
    module, cfg, ckpt, h5 = load_run(run, which, data, batch_size=batch_size,
                                     workers=workers, noise=noise, mjp=mjp)
    dm = make_datamodule(cfg, h5)
    prepare_data(dm, stages=(SPLIT_STAGES[split],))
    loader = dm.test_dataloader() if split == "test" else dm.val_dataloader()
    device = torch.device("cuda" if accelerator in ("auto", "gpu") and torch.cuda.is_available()
                          else "cpu")
    if accelerator == "gpu" and device.type != "cuda":
        raise C.ConfigError("--accelerator gpu: no CUDA device available")
    module.to(device)
    net, task = module.net, module.task
    parts: dict = {}
    strings: dict = {k: [] for k in ("video_id", "pedestrian_id", "age", "gender")}
    if progress:
        from tqdm import tqdm

        loader = tqdm(loader, desc=f"predicting {split}", unit="batch", file=sys.stderr)
    with torch.no_grad():
        for batch in loader:
            batch = _to(batch, device)
            arrays = _outputs(task, net.forward_batch(batch), batch, net)
            meta = batch["meta"]
            arrays.update(clip_id=_np(meta["clip_id"]), row=_np(meta["row"]),
                          start_frame=_np(meta["start_frame"]), label=_np(batch["label"]))
            for k, v in arrays.items():
                parts.setdefault(k, []).append(v)
            for k in strings:
                strings[k] += list(meta[k])
    L = dm.datasets[split].clip_length
    sl = net.frame_slice(L)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(out, force=force) as tmp:
        with h5py.File(tmp, "w") as f:
            for k, v in parts.items():
                f.create_dataset(k, data=np.concatenate(v))
            for k, v in strings.items():
                f.create_dataset(k, data=np.array(v, dtype=h5py.string_dtype()))
            f.attrs.update({"created_by": "bsp-predict", "task": task,
                            "model": module.hparams["model"], "checkpoint": str(ckpt),
                            "source": str(dm.h5_path), "split": split,
                            "frame_start": sl.start or 0, "frame_stop": sl.stop or L,
                            "clip_length": L,
                            "hparams_json": json.dumps(module.hparams["hparams"], default=str),
                            "units": "metres" if task == "lifting" else "pixels"})
    n = int(sum(len(v) for v in parts["label"]))
    return PredictResult(path=out, task=task, model=module.hparams["model"], split=split,
                         clips=n, datasets=sorted(list(parts) + list(strings)))


def _to(batch: dict, device):
    if device.type == "cpu":
        return batch
    return {k: (_to(v, device) if isinstance(v, dict) else
                v.to(device) if hasattr(v, "to") else v) for k, v in batch.items()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="bsp-predict",
        description="Write a bsp-train model's de-normalised outputs (pixels or metres) for "
                    "one split, with clip ids, to an HDF5 file.",
        epilog="exit codes: 0 success, 1 bad data/run/checkpoint, 2 bad arguments, 3 output "
               "exists (use --force). docs: docs/training.md",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("run", metavar="RUN_OR_CKPT", help="run directory or .ckpt")
    p.add_argument("--out", required=True, metavar="PREDS.h5", help="HDF5 file to write")
    p.add_argument("--data", default=None, metavar="DATASET_OR_H5",
                   help="data to predict on (default: the run's)")
    p.add_argument("--split", default="test", choices=("test", "val"))
    p.add_argument("--which", default="best", choices=("best", "last"),
                   help="checkpoint of a run directory")
    p.add_argument("--batch-size", type=int, default=None, help="default: the run's")
    p.add_argument("--workers", type=int, default=None, help="DataLoader worker processes")
    p.add_argument("--accelerator", default="auto", choices=C.ACCELERATORS)
    p.add_argument("--noise", type=float, default=None, help="override the run's input noise")
    p.add_argument("--mjp", default=None, help="override the run's missing-joint probability")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        res = predict(args.run, args.out, args.data, split=args.split, which=args.which,
                      batch_size=args.batch_size, workers=args.workers,
                      accelerator=args.accelerator, noise=args.noise, mjp=args.mjp,
                      force=args.force, progress=not args.quiet)
    except (C.ConfigError, ValueError) as exc:
        print(f"bsp-predict: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"bsp-predict: {exc}", file=sys.stderr)
        return exc.code
    if not args.quiet:
        print(f"wrote {res.path}: {res.clips} {res.split} clips of {res.task}/{res.model} "
              f"({', '.join(res.datasets)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
