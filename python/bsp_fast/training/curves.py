"""``curves.png``: loss and the task's main metrics per epoch, from a run's CSV logs."""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path

__all__ = ["read_logs", "plot_curves", "MAIN_METRICS"]

#: The metrics drawn (and tabulated) per task, with their labels.
MAIN_METRICS = {
    "classification": (("f1", "F1"), ("precision", "precision"), ("recall", "recall")),
    "autoencoder": (("pck_0.05", "PCK@0.05"), ("pckhn_0.1", "PCKhn@0.1")),
    "lifting": (("mpjpe_mm", "MPJPE (mm)"), ("n_mpjpe_mm", "N-MPJPE (mm)"),
                ("pa_mpjpe_mm", "PA-MPJPE (mm)"), ("mpjve_mm", "MPJVE (mm)")),
    "pose_estimation": (("pck_0.05", "PCK@0.05"), ("pckhn_0.1", "PCKhn@0.1")),
}


def _version(path: Path) -> int:
    m = re.search(r"version_(\d+)", str(path))
    return int(m.group(1)) if m else 0


def read_logs(run_dir) -> dict:
    """Per-epoch values of every logged column, over all ``logs/version_*/metrics.csv``
    (a resumed run adds a version): ``{column: {epoch: last value logged in that epoch}}``."""
    files = sorted(Path(run_dir).glob("logs/version_*/metrics.csv"), key=_version)
    out: dict = {}
    for f in files:
        with open(f, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                try:
                    epoch = int(float(row.get("epoch") or "nan"))
                except ValueError:
                    continue
                for key, text in row.items():
                    if key in ("epoch", "step") or text in (None, ""):
                        continue
                    try:
                        value = float(text)
                    except ValueError:
                        continue
                    out.setdefault(key, {})[epoch] = value
    return out


def plot_curves(run_dir, task: str, out_path=None, initial: dict | None = None,
                title: str | None = None) -> Path | None:
    """Draws train/val loss and the task's val metrics per epoch (dashed: the initial
    metrics of the trivial baseline on val). Returns the PNG path, or None when nothing
    was logged per epoch."""
    logs = read_logs(run_dir)
    if not any(k.startswith(("train/", "val/")) for k in logs):
        return None
    from .._extras import require

    matplotlib = require("matplotlib", "bsp-train (curves.png)", extra="torch")
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    metrics = [(k, label) for k, label in MAIN_METRICS[task] if f"val/{k}" in logs]
    fig, axes = plt.subplots(1, 1 + bool(metrics), figsize=(11 if metrics else 6, 4),
                             squeeze=False)
    ax = axes[0, 0]
    for key, label in (("train/loss", "train loss"), ("val/loss", "val loss")):
        if key in logs:
            epochs = sorted(logs[key])
            ax.plot([e + 1 for e in epochs], [logs[key][e] for e in epochs], marker=".",
                    label=label)
    base = (initial or {}).get("loss")
    if base is not None and math.isfinite(base):
        ax.axhline(base, ls="--", c="grey", lw=1, label="initial (val)")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss")
    ax.set_yscale("log" if _positive(logs, ("train/loss", "val/loss")) else "linear")
    ax.grid(alpha=0.3)
    ax.legend()
    if metrics:
        ax = axes[0, 1]
        for i, (key, label) in enumerate(metrics):
            series = logs[f"val/{key}"]
            epochs = sorted(series)
            line, = ax.plot([e + 1 for e in epochs], [series[e] for e in epochs], marker=".",
                            label=f"val {label}")
            base = (initial or {}).get(key)
            if base is not None and math.isfinite(base):
                ax.axhline(base, ls="--", lw=1, c=line.get_color())
        ax.set_xlabel("epoch")
        ax.set_ylabel("mm" if task == "lifting" else "")
        ax.grid(alpha=0.3)
        ax.legend(title="dashed: initial metrics" if initial else None)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out = Path(out_path) if out_path is not None else Path(run_dir) / "curves.png"
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def _positive(logs: dict, keys) -> bool:
    values = [v for k in keys if k in logs for v in logs[k].values()]
    return bool(values) and min(values) > 0 and max(values) / min(values) > 20
