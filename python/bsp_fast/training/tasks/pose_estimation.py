"""Crops -> 2D joints in crop pixels, scored with one protocol for every row
(docs/metrics.md, "Pose estimation protocol"):

* ``pck_0.05``: PCK@0.05 over every ground-truth joint of every frame that has a crop,
  normalised by the diagonal of the box of those joints (as the report);
* ``pckhn_0.1``: PCKhn@0.1, normalised by the true hips-neck distance;
* ``pck_0.05_visible`` / ``pck_0.05_occluded``: the same PCK@0.05 (same normaliser) over
  the joints the mask shows (``frames/joint_visible``) and over the others;
* ``pck_0.05_hands`` / ``pck_0.05_feet``: the same PCK@0.05 over the hand joints
  (:data:`HANDS`) and over the foot joints, ankle to toe end (:data:`FEET`), both sides:
  the small, fast end effectors an average skeleton cannot place;
* ``pck_0.05_aligned`` / ``pckhn_0.1_aligned``: the report's hips-aligned protocol, the
  prediction translated so its hips lie on the true hips (the hips not counted);
* extra: ``pck_0.05/<joint>`` per joint and ``fully_occluded_frames`` (scored frames
  without a crop: no pedestrian pixel under mask boxes; not scored).
"""
from __future__ import annotations

import functools

from ...metrics.spec import Metric
from ...skeleton import JOINT_NAMES
from .base import Task

__all__ = ["PoseEstimation", "HANDS", "FEET"]

HANDS = ("crl_hand__L", "crl_hand__R")
FEET = ("crl_foot__L", "crl_toe__L", "crl_toeEnd__L", "crl_foot__R", "crl_toe__R",
        "crl_toeEnd__R")

_PER_JOINT = tuple(Metric(f"pck_0.05/{n}", f"PCK@0.05 {n}", "fraction", "higher", "pct")
                   for n in JOINT_NAMES)


@functools.lru_cache(maxsize=None)
def _joints(names, device):
    """The ``(26,)`` mask of ``names``, built once per device (every test batch asks)."""
    import torch

    mask = torch.zeros(len(JOINT_NAMES), dtype=torch.bool, device=device)
    mask[[JOINT_NAMES.index(n) for n in names]] = True
    return mask


class PoseEstimation(Task):
    name = "pose_estimation"
    description = "pedestrian crops -> 2D joints"
    batch_keys = ("inputs", "visible", "targets", "crop_box", "label", "meta")
    baseline = "mean crop skeleton"
    image_inputs = True
    metrics = (Metric("pck_0.05", "PCK@0.05", "fraction", "higher", "pct"),
               Metric("pckhn_0.1", "PCKhn@0.1", "fraction", "higher", "pct"),
               Metric("pck_0.05_visible", "PCK@0.05 visible", "fraction", "higher", "pct"),
               Metric("pck_0.05_occluded", "PCK@0.05 occluded", "fraction", "higher", "pct"),
               Metric("pck_0.05_hands", "PCK@0.05 hands", "fraction", "higher", "pct"),
               Metric("pck_0.05_feet", "PCK@0.05 feet", "fraction", "higher", "pct"),
               Metric("pck_0.05_aligned", "PCK@0.05 hips-aligned", "fraction", "higher", "pct"),
               Metric("pckhn_0.1_aligned", "PCKhn@0.1 hips-aligned", "fraction", "higher",
                      "pct"))
    extra_metrics = _PER_JOINT + (Metric("fully_occluded_frames", "fully occluded frames",
                                         "frames", "none", ".0f"),)
    curves = ("pck_0.05", "pckhn_0.1")
    breakdown_scores = "pose_pairs"

    def dataset_options(self, cfg: dict) -> dict:
        """Train-time box jitter (``box_jitter_scale``, ``box_jitter_shift``; default off):
        the train split's crop boxes perturbed per frame and re-cut from the context crops;
        ``image_augment`` (default off): flips, zoom, shift, rotation (``image_rotation``)
        and colour jitter of the train crops (``data.images.ImageAugment``)."""
        scale = cfg.get("box_jitter_scale", 0.0) or 0.0
        shift = cfg.get("box_jitter_shift", 0.0) or 0.0
        out = {"box_jitter": (float(scale), float(shift))} if scale or shift else {}
        if cfg.get("image_augment"):  # the data module keeps it to the train split
            out.update(augment=True, image_rotation=float(cfg.get("image_rotation", 15.0)))
        return out

    def metric_modules(self) -> dict:
        from ... import metrics as M

        return {"pck_0.05": M.PCK(alpha=0.05, norm="bbox"),
                "pckhn_0.1": M.PCK(alpha=0.1, norm="hips_neck"),
                "pck_0.05_visible": M.PCK(alpha=0.05, norm="bbox"),
                "pck_0.05_occluded": M.PCK(alpha=0.05, norm="bbox"),
                "pck_0.05_hands": M.PCK(alpha=0.05, norm="bbox"),
                "pck_0.05_feet": M.PCK(alpha=0.05, norm="bbox"),
                "pck_0.05_aligned": M.PCK(alpha=0.05, norm="bbox", align="hips"),
                "pckhn_0.1_aligned": M.PCK(alpha=0.1, norm="hips_neck", align="hips"),
                "pck_0.05_per_joint": M.PCKPerJoint(alpha=0.05, norm="bbox",
                                                    prefix="pck_0.05/"),
                "fully_occluded_frames": M.FrameCount()}

    def pose_pairs(self, output, batch, model) -> tuple:
        """``(prediction, target, present)`` in crop pixels on the scored frames, as
        ``pck_0.05`` scores them: ``present`` is every joint of a frame with a crop."""
        import torch

        sl = self.scored_frames(model, batch["targets"].shape[1])
        target = batch["targets"][:, sl].float()
        return output, target, torch.isfinite(target).all(-1)

    def update_metrics(self, scores, output, batch, model) -> None:
        import torch

        sl = self.scored_frames(model, batch["targets"].shape[1])
        _, target, present = self.pose_pairs(output, batch, model)
        visible = batch["visible"][:, sl].bool()
        for key in ("pck_0.05", "pckhn_0.1", "pck_0.05_aligned", "pckhn_0.1_aligned",
                    "pck_0.05_per_joint"):
            scores[key].update(output, target, visible=present)
        scores["pck_0.05_visible"].update(output, target, visible=present, select=visible)
        scores["pck_0.05_occluded"].update(output, target, visible=present, select=~visible)
        for key, joints in (("pck_0.05_hands", HANDS), ("pck_0.05_feet", FEET)):
            scores[key].update(output, target, visible=present,
                               select=_joints(joints, present.device).expand_as(present))
        box = batch["crop_box"][:, sl]
        scores["fully_occluded_frames"].update(~torch.isfinite(box).all(-1))

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
