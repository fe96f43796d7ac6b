"""Denoising/completing normalised 2D: PCK@0.05 and PCKhn@0.1 on de-normalised pixels,
and the realised missing-joint ratio of the inputs (MJR)."""
from __future__ import annotations

from ...metrics.spec import Metric
from .base import Task

__all__ = ["Autoencoder"]


class Autoencoder(Task):
    name = "autoencoder"
    description = "denoise/complete normalised 2D poses"
    batch_keys = ("inputs", "visible", "targets", "shift", "scale", "target_shift",
                  "target_scale", "label", "meta")
    baseline = "identity (noisy input)"
    metrics = (Metric("mjr", "MJR", "fraction", "none", ".4f"),
               Metric("pck_0.05", "PCK@0.05", "fraction", "higher", "pct"),
               Metric("pckhn_0.1", "PCKhn@0.1", "fraction", "higher", "pct"))
    curves = ("pck_0.05", "pckhn_0.1")
    deformed_inputs = True
    augments = True
    breakdown_scores = "pose_pairs"

    def metric_modules(self) -> dict:
        from torchmetrics import MeanMetric

        from ... import metrics as M

        return {"pck_0.05": M.PCK(alpha=0.05, norm="bbox"),
                "pckhn_0.1": M.PCK(alpha=0.1, norm="hips_neck"), "mjr": MeanMetric()}

    def pose_pairs(self, output, batch, model) -> tuple:
        """``(prediction, target, present)`` as PCK scores them, on the scored frames:
        output and clean target both mapped back to pixels with the target's shift and
        scale, ``present`` the joints present in the target (the hips always)."""
        from ...models.base import present_joints

        sl = self.scored_frames(model, batch["targets"].shape[1])
        target = batch["targets"][:, sl].float()
        scale = batch["target_scale"][:, sl, None, None].float()
        shift = batch["target_shift"][:, sl, None, :].float()
        present = present_joints(target)
        return output * scale + shift, target * scale + shift, present

    def update_metrics(self, scores, output, batch, model) -> None:
        """PCK of :meth:`pose_pairs`; MJR of the inputs."""
        pred_px, gt_px, present = self.pose_pairs(output, batch, model)
        scores["pck_0.05"].update(pred_px, gt_px, visible=present)
        scores["pckhn_0.1"].update(pred_px, gt_px, visible=present)
        missing = (~batch["visible"]).float()
        scores["mjr"].update(missing.mean(), missing.numel())

    def predictions(self, output, batch, model) -> dict:
        """``pixels``: de-normalised with the *input's* normalisation (no ground truth);
        ``pixels_scored``: with the clean target's, as scored (equal without noise/MJP)."""
        import torch

        sl = self.scored_frames(model, batch["targets"].shape[1])
        scale, shift = batch["scale"][:, sl, None, None], batch["shift"][:, sl, None, :]
        vis = batch["visible"][:, sl, :, None]
        tscale = batch["target_scale"][:, sl, None, None]
        tshift = batch["target_shift"][:, sl, None, :]
        return {"pixels": output * scale + shift, "pixels_scored": output * tscale + tshift,
                "normalised": output,
                "input_pixels": torch.where(vis, batch["inputs"][:, sl] * scale + shift, 0.0),
                "target_pixels": batch["targets"][:, sl] * tscale + tshift,
                "frames": batch["meta"]["frames"][:, sl]}
