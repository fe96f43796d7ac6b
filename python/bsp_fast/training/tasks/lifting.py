"""2D -> 3D lifting: MPJPE, N-MPJPE, PA-MPJPE in mm and MPJVE in mm per frame, after
de-normalising the output with the reference skeleton's hips-neck length of the clip's
(age, gender). Every lifting model predicts every frame of a clip (PoseFormer pads the clip
edges), so every row is scored on the same frames; the ``*_centre`` metrics score frames
``[CENTRE_MARGIN, L - CENTRE_MARGIN)`` again, the frames the report scored PoseFormer on."""
from __future__ import annotations

from ...metrics.spec import Metric
from .base import Task

__all__ = ["Lifting", "hips_neck_lengths", "CENTRE_MARGIN"]

#: the report's PoseFormer (receptive field 9) was scored on frames [9 // 2, L - 9 // 2) only
CENTRE_MARGIN = 4
_KEYS = ("mpjpe_mm", "n_mpjpe_mm", "pa_mpjpe_mm", "mpjve_mm")


def hips_neck_lengths(meta: dict, device=None):
    """(B,) float32 tensor: the reference-skeleton hips-neck lengths in metres of a
    batch's (age, gender) (``bsp_fast.skeleton.hips_neck_length``)."""
    import torch

    from ... import skeleton

    values = skeleton.hips_neck_length(list(meta["age"]), list(meta["gender"]))
    return torch.as_tensor(values, dtype=torch.float32, device=device)


class Lifting(Task):
    name = "lifting"
    description = "2D poses -> 3D poses"
    batch_keys = ("inputs", "visible", "targets", "targets_m", "label", "meta")
    baseline = "mean training pose"
    metrics = (Metric("mpjpe_mm", "MPJPE", "mm", "lower", ".2f"),
               Metric("n_mpjpe_mm", "N-MPJPE", "mm", "lower", ".2f"),
               Metric("pa_mpjpe_mm", "PA-MPJPE", "mm", "lower", ".2f"),
               Metric("mpjve_mm", "MPJVE", "mm per frame", "lower", ".2f"))
    extra_metrics = (Metric("mpjpe_mm_centre", "MPJPE, centre frames", "mm", "lower", ".2f"),
                     Metric("n_mpjpe_mm_centre", "N-MPJPE, centre frames", "mm", "lower", ".2f"),
                     Metric("pa_mpjpe_mm_centre", "PA-MPJPE, centre frames", "mm", "lower", ".2f"),
                     Metric("mpjve_mm_centre", "MPJVE, centre frames", "mm per frame", "lower",
                            ".2f"))
    curves = ("mpjpe_mm", "n_mpjpe_mm", "pa_mpjpe_mm", "mpjve_mm")
    prediction_units = "metres"
    breakdown_scores = "joint_error_mm"
    breakdown_bins = "camera_distance"

    def dataset_options(self, cfg: dict) -> dict:
        return {"lifting_target": cfg["lifting_target"]}

    def metric_modules(self) -> dict:
        from ... import metrics as M

        kinds = {"mpjpe_mm": M.MPJPE, "n_mpjpe_mm": M.NMPJPE, "pa_mpjpe_mm": M.PAMPJPE,
                 "mpjve_mm": M.MPJVE}
        return {k + end: kinds[k]() for end in ("", "_centre") for k in _KEYS}

    def metres(self, output, batch, model) -> tuple:
        """``(prediction, target)`` in metres on the scored frames: the normalised output
        scaled by the reference hips-neck length, its hips put on the target's hips."""
        from ... import metrics as M

        sl = self.scored_frames(model, batch["targets_m"].shape[1])
        gt_m = batch["targets_m"][:, sl].float()
        hips_neck = hips_neck_lengths(batch["meta"], device=output.device)
        return M.denormalise_lifting(output, gt_m, hips_neck), gt_m

    def update_metrics(self, scores, output, batch, model) -> None:
        pred_m, gt_m = self.metres(output, batch, model)
        pred_mm, gt_mm = pred_m * 1000.0, gt_m * 1000.0
        for key in _KEYS:
            scores[key].update(pred_mm, gt_mm)
        L = batch["targets_m"].shape[1]  # the centre frames, as indices of the output
        sl = self.scored_frames(model, L)
        start = sl.start or 0
        lo = max(CENTRE_MARGIN, start) - start
        hi = min(L - CENTRE_MARGIN, sl.stop if sl.stop is not None else L) - start
        if hi - lo >= 2:  # MPJVE needs two frames
            for key in _KEYS:
                scores[key + "_centre"].update(pred_mm[:, lo:hi], gt_mm[:, lo:hi])

    def predictions(self, output, batch, model) -> dict:
        """``metres``: hips at the origin, reference-skeleton scale; ``metres_aligned``:
        hips on the target's, as scored."""
        aligned, gt_m = self.metres(output, batch, model)
        hn = hips_neck_lengths(batch["meta"], device=output.device)
        sl = self.scored_frames(model, batch["targets_m"].shape[1])
        return {"metres": output * hn[:, None, None, None], "normalised": output,
                "metres_aligned": aligned, "target_metres": gt_m,
                "frames": batch["meta"]["frames"][:, sl]}
