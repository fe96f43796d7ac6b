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
    ``RUN/test_box_noise.json``, their sums per test recording (suffixed the same) added
    to the ``test`` section of ``RUN/test_per_recording.json``, so that their cells and
    findings get intervals over seeds and recordings like the clean ones."""
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
        if res.per_recording is not None:
            _add_per_recording(run_dir, res.per_recording)
        write_text(path, json.dumps(doc, indent=1))
    return {f"{k}_noisy": v for k, v in doc["test"].items() if k != "loss"}


def _add_per_recording(run_dir: Path, noisy: dict) -> None:
    """Adds the noisy-box sums (``NAME_noisy``) to the run's ``test_per_recording.json``:
    the same test recordings in the same order, or RunError (nothing written)."""
    from ..training.runs import PER_RECORDING_FILE as FILE

    path = run_dir / FILE
    if not path.is_file():
        return  # a run from before per-recording sums: its noisy cells stay without them
    doc = json.loads(path.read_text(encoding="utf-8"))
    test = doc.get("test") or {}
    if list(test.get("recordings", [])) != list(noisy["recordings"]):
        raise RunError(f"{path}: the noisy-box test scored other recordings than the run's "
                       "test; per-recording sums not merged")
    for name, sums in noisy["metrics"].items():
        test["metrics"][f"{name}_noisy"] = sums
        doc.setdefault("empty", {})[f"{name}_noisy"] = doc.get("empty", {}).get(name)
    write_text(path, json.dumps(doc))
