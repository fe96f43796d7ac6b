"""What each task scores, as one ``torch.nn.Module`` of streaming metrics per split.

* classification: F1 of the crossing class, precision, recall, accuracy (argmax of two
  logits or sigmoid >= 0.5 of one);
* autoencoder: PCK@0.05 (joint-bbox diagonal) and PCKhn@0.1 (hips-neck length) on
  de-normalised **pixels** (output and clean target both mapped back with the target's
  shift and scale), over the joints present in the target; the realised missing-joint
  ratio of the inputs (MJR);
* lifting: the prediction is de-normalised with the hips-neck length of the clip's
  reference skeleton (age, gender) and its hips put on the target's hips, then MPJPE,
  N-MPJPE, PA-MPJPE and MPJVE in mm on the frames the model predicts (``frame_slice``:
  every frame, for every lifting model), and again on the centre frames
  ``[CENTRE_MARGIN, L - CENTRE_MARGIN)`` (keys ``*_centre``: the frames the report scored
  PoseFormer on, the same frames for every row); MPJVE in mm per frame;
* pose_estimation: PCK@0.05 and PCKhn@0.1 in crop pixels over the visible joints.

Every value is a global sum over the split divided by a global count (torchmetrics
states, reduced over DDP processes), never a mean of batch means. ``loss`` is the model's
loss averaged over clips.
"""
from __future__ import annotations

import functools

import torch

__all__ = ["TaskMetrics", "hips_neck_lengths", "UNITS", "CENTRE_MARGIN"]

HIPS, NECK = 1, 8
#: the report's PoseFormer (receptive field 9) scored frames [9 // 2, L - 9 // 2) only
CENTRE_MARGIN = 4
_LIFTING = ("mpjpe_mm", "n_mpjpe_mm", "pa_mpjpe_mm", "mpjve_mm")
UNITS = {"mpjpe_mm": "mm", "n_mpjpe_mm": "mm", "pa_mpjpe_mm": "mm",
         "mpjve_mm": "mm per frame",
         **{f"{k}_centre": "mm per frame" if k == "mpjve_mm" else "mm" for k in _LIFTING},
         "pck_0.05": "fraction", "pckhn_0.1": "fraction", "mjr": "fraction",
         "f1": "fraction", "precision": "fraction", "recall": "fraction",
         "accuracy": "fraction"}


@functools.lru_cache(maxsize=None)
def _hips_neck(age: str, gender: str) -> float:
    from .. import skeleton

    helper = getattr(skeleton, "hips_neck_length", None)
    if helper is not None:
        return float(helper(age, gender))
    from ..geometry import forward_kinematics

    comp = forward_kinematics(skeleton.reference_pose((age, gender), "relative"))
    return float(((comp[NECK, :3] - comp[HIPS, :3]) ** 2).sum() ** 0.5)


def hips_neck_lengths(meta: dict, device=None) -> torch.Tensor:
    """(B,) reference-skeleton hips-neck lengths in metres of a batch's (age, gender)."""
    values = [_hips_neck(a, g) for a, g in zip(meta["age"], meta["gender"])]
    return torch.tensor(values, dtype=torch.float32, device=device)


class TaskMetrics(torch.nn.Module):
    """``update_loss(loss, n)``, ``update(output, batch, model)``, ``compute() -> dict``
    of floats, ``reset()``."""

    def __init__(self, task: str):
        super().__init__()
        from torchmetrics import MeanMetric

        from .. import metrics as M

        self.task = task
        self.loss = MeanMetric()
        if task == "classification":
            self.scores = torch.nn.ModuleDict({"cls": M.ClassificationMetrics()})
        elif task in ("autoencoder", "pose_estimation"):
            self.scores = torch.nn.ModuleDict({
                "pck_0.05".replace(".", "_"): M.PCK(alpha=0.05, norm="bbox"),
                "pckhn_0.1".replace(".", "_"): M.PCK(alpha=0.1, norm="hips_neck")})
            if task == "autoencoder":
                self.scores["mjr"] = MeanMetric()
        elif task == "lifting":
            kinds = {"mpjpe_mm": M.MPJPE, "n_mpjpe_mm": M.NMPJPE, "pa_mpjpe_mm": M.PAMPJPE,
                     "mpjve_mm": M.MPJVE}
            self.scores = torch.nn.ModuleDict(
                {k + end: kinds[k]() for end in ("", "_centre") for k in _LIFTING})
        else:
            raise ValueError(f"task must be one of ['classification', 'autoencoder', "
                             f"'lifting', 'pose_estimation'], got {task!r}")

    def update_loss(self, loss: torch.Tensor, n: int) -> None:
        loss = loss.detach().float()
        if torch.isfinite(loss):
            self.loss.update(loss, n)

    @torch.no_grad()
    def update(self, output: torch.Tensor, batch: dict, model) -> None:
        output = output.detach().float()
        getattr(self, f"_{self.task}")(output, batch, model)

    def _classification(self, output, batch, model) -> None:
        self.scores["cls"].update(output, batch["label"])

    def _autoencoder(self, output, batch, model) -> None:
        L = batch["targets"].shape[1]
        sl = model.frame_slice(L)
        target = batch["targets"][:, sl].float()
        scale = batch["target_scale"][:, sl, None, None].float()
        shift = batch["target_shift"][:, sl, None, :].float()
        present = (target != 0).any(-1)
        present[..., HIPS] = True  # a missing joint is exactly (0, 0); the hips always count
        pred_px, gt_px = output * scale + shift, target * scale + shift
        self.scores["pck_0_05"].update(pred_px, gt_px, visible=present)
        self.scores["pckhn_0_1"].update(pred_px, gt_px, visible=present)
        missing = (~batch["visible"]).float()
        self.scores["mjr"].update(missing.mean(), missing.numel())

    def _pose_estimation(self, output, batch, model) -> None:
        sl = model.frame_slice(batch["targets"].shape[1])
        target, visible = batch["targets"][:, sl].float(), batch["visible"][:, sl]
        self.scores["pck_0_05"].update(output, target, visible=visible)
        self.scores["pckhn_0_1"].update(output, target, visible=visible)

    def _lifting(self, output, batch, model) -> None:
        from .. import metrics as M

        sl = model.frame_slice(batch["targets_m"].shape[1])
        gt_m = batch["targets_m"][:, sl].float()
        hips_neck = hips_neck_lengths(batch["meta"], device=output.device)
        pred_mm = M.denormalise_lifting(output, gt_m, hips_neck) * 1000.0
        gt_mm = gt_m * 1000.0
        for key in _LIFTING:
            self.scores[key].update(pred_mm, gt_mm)
        L = batch["targets_m"].shape[1]  # the centre frames, as indices of the output
        lo = max(CENTRE_MARGIN, sl.start or 0) - (sl.start or 0)
        hi = min(L - CENTRE_MARGIN, sl.stop if sl.stop is not None else L) - (sl.start or 0)
        if hi - lo >= 2:  # MPJVE needs two frames
            for key in _LIFTING:
                self.scores[key + "_centre"].update(pred_mm[:, lo:hi], gt_mm[:, lo:hi])

    def compute(self) -> dict:
        out = {"loss": _scalar(self.loss) if self.loss.update_count else float("nan")}
        for name, metric in self.scores.items():
            if not metric.update_count:
                continue
            value = metric.compute()
            if isinstance(value, dict):
                out.update({k: float(v) for k, v in value.items()})
            else:
                out[name.replace("_0_", "_0.")] = float(value)
        return out

    def reset(self) -> None:
        self.loss.reset()
        for metric in self.scores.values():
            metric.reset()


def _scalar(metric) -> float:
    return float(metric.compute())
