"""Pose-estimation tables score each trained row again on the test crops of noisy boxes
(``box_noise: {scale, shift}`` in the table file; ``bsp-eval --box-noise``), with and
without ``--seeds``."""
from __future__ import annotations

import json
from pathlib import Path

from ..atomic import write_text
from ..training.runs import RunError

__all__ = ["noisy_box_metrics"]


def noisy_box_metrics(tab: dict, run_dir: Path, force: bool, quiet: bool, log) -> dict:
    """A table with ``box_noise: {scale, shift}`` (pose estimation) also scores each trained
    row's best checkpoint on the test crops of noisy boxes (``bsp-eval --box-noise``);
    the metrics come back with the suffix ``_noisy`` and are kept in
    ``RUN/test_box_noise.json``."""
    spec = tab.get("box_noise")
    if not spec:
        return {}
    path = run_dir / "test_box_noise.json"
    if path.is_file() and not force:
        doc = json.loads(path.read_text(encoding="utf-8"))
    else:
        from ..training.evaluate import evaluate

        noise = (float(spec["scale"]), float(spec["shift"]))
        log(f"[{run_dir.name}] scoring the test split with noisy boxes (scale ±{noise[0]:g}, "
            f"shift ±{noise[1]:g} of the side)")
        try:
            res = evaluate(run_dir, "test", box_noise=noise, quiet=quiet)
        except (ValueError, RunError) as exc:
            log(f"[{run_dir.name}] no noisy-box scores: {exc}")
            return {}
        doc = {"box_noise": {"scale": noise[0], "shift": noise[1]}, "test": res.metrics}
        write_text(path, json.dumps(doc, indent=1))
    return {f"{k}_noisy": v for k, v in doc["test"].items() if k != "loss"}
