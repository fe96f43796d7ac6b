"""Crops -> 2D joints in crop pixels: PCK@0.05 and PCKhn@0.1 over the visible joints."""
from __future__ import annotations

from .base import Metric, Task

__all__ = ["PoseEstimation"]


class PoseEstimation(Task):
    name = "pose_estimation"
    description = "pedestrian crops -> 2D joints"
    batch_keys = ("inputs", "visible", "targets", "crop_box", "label", "meta")
    baseline = "mean crop skeleton"
    metrics = (Metric("pck_0.05", "PCK@0.05", "fraction", "higher", "pct"),
               Metric("pckhn_0.1", "PCKhn@0.1", "fraction", "higher", "pct"))
    curves = ("pck_0.05", "pckhn_0.1")

    def dataset_options(self, cfg: dict) -> dict:
        """Train-time box jitter (``box_jitter_scale``, ``box_jitter_shift``; default off):
        the train split's crop boxes perturbed per frame and re-cut from the context crops."""
        scale, shift = cfg.get("box_jitter_scale", 0.0) or 0.0, cfg.get("box_jitter_shift", 0.0) or 0.0
        return {"box_jitter": (float(scale), float(shift))} if scale or shift else {}

    def metric_modules(self) -> dict:
        from ... import metrics as M

        return {"pck_0.05": M.PCK(alpha=0.05, norm="bbox"),
                "pckhn_0.1": M.PCK(alpha=0.1, norm="hips_neck")}

    def update_metrics(self, scores, output, batch, model) -> None:
        sl = self.scored_frames(model, batch["targets"].shape[1])
        target, visible = batch["targets"][:, sl].float(), batch["visible"][:, sl]
        scores["pck_0.05"].update(output, target, visible=visible)
        scores["pckhn_0.1"].update(output, target, visible=visible)

    def predictions(self, output, batch, model) -> dict:
        """``pixels``: crop pixels mapped to image pixels through each frame's crop box."""
        import torch

        sl = self.scored_frames(model, batch["targets"].shape[1])
        box = batch["crop_box"][:, sl].float()
        S = batch["inputs"].shape[-1]
        size = torch.stack([box[..., 2] - box[..., 0], box[..., 3] - box[..., 1]], -1)
        return {"crop_pixels": output, "pixels": output * (size / S)[..., None, :]
                + box[..., None, :2],
                "target_crop_pixels": batch["targets"][:, sl], "visible": batch["visible"][:, sl],
                "frames": batch["meta"]["frames"][:, sl]}
