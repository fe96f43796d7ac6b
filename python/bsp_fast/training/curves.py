"""``curves.png``: loss and the task's main metrics per epoch, from a run's CSV logs.

The metrics drawn are the task object's ``curves``, in the unit of the tables (PCK in %,
errors in mm); a dotted line marks the best epoch (the checkpoint that was tested) and the
epoch axis has whole-number ticks.
"""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path

from .tasks import get_task

__all__ = ["read_logs", "plot_curves", "curves_figure", "best_epoch_of"]


def _version(path: Path) -> int:
    m = re.search(r"version_(\d+)", str(path))
    return int(m.group(1)) if m else 0


def read_logs(run_dir) -> dict:
    """Per-epoch values of every logged column, over all ``logs/version_*/metrics.csv``
    (a resumed run adds a version): ``{column: {epoch: last value logged in that epoch}}``;
    ``step`` holds the optimiser-update index of each epoch's validation row (Lightning
    logs epoch-end values at the index of the epoch's last update)."""
    files = sorted(Path(run_dir).glob("logs/version_*/metrics.csv"), key=_version)
    out: dict = {}
    for f in files:
        with open(f, newline="", encoding="utf-8") as fh:
            for row in csv.DictReader(fh):
                try:
                    epoch = int(float(row.get("epoch") or "nan"))
                except ValueError:
                    continue
                if any(k.startswith("val/") and t not in (None, "") for k, t in row.items()) \
                        and row.get("step") not in (None, ""):
                    out.setdefault("step", {})[epoch] = int(float(row["step"]))
                for key, text in row.items():
                    if key in ("epoch", "step") or text in (None, ""):
                        continue
                    try:
                        value = float(text)
                    except ValueError:
                        continue
                    out.setdefault(key, {})[epoch] = value
    return out


def best_epoch_of(logs: dict) -> int | None:
    """1-based epoch of the lowest logged val loss (what the best checkpoint monitors)."""
    val = {e: v for e, v in logs.get("val/loss", {}).items() if math.isfinite(v)}
    return min(val, key=val.get) + 1 if val else None


def curves_figure(logs: dict, task: str, initial: dict | None = None,
                  title: str | None = None, best_epoch: int | None = None):
    """The matplotlib figure of :func:`plot_curves` from :func:`read_logs`' ``logs``:
    train/val loss, and the task's val metrics in the tables' units (dashed: the trivial
    baseline's ``initial`` val metrics; dotted: ``best_epoch``, 1-based, by default the
    epoch of the lowest val loss)."""
    from .._extras import require

    matplotlib = require("matplotlib", "bsp-train (curves.png)", extra="torch")
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    spec = get_task(task)
    metrics = [spec.metric(k) for k in spec.curves if f"val/{k}" in logs]
    best = best_epoch_of(logs) if best_epoch is None else best_epoch
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
    ax.set_ylabel("loss")
    ax.set_yscale("log" if _positive(logs, ("train/loss", "val/loss")) else "linear")
    if metrics:
        mx = axes[0, 1]
        for m in metrics:
            series = logs[f"val/{m.key}"]
            epochs = sorted(series)
            line, = mx.plot([e + 1 for e in epochs], [m.display(series[e]) for e in epochs],
                            marker=".", label=f"val {m.header}")
            base = (initial or {}).get(m.key)
            if base is not None and math.isfinite(base):
                mx.axhline(m.display(base), ls="--", lw=1, c=line.get_color())
        units = {m.display_unit for m in metrics}
        mx.set_ylabel(units.pop() if len(units) == 1 else "")
    for i, a in enumerate(axes[0]):
        if best is not None:
            a.axvline(best, ls=":", c="black", lw=1,
                      label=f"best epoch ({best})" if i == 0 else None)
        a.set_xlabel("epoch")
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
        a.grid(alpha=0.3)
        a.legend(title="dashed: initial metrics" if i and initial else None)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_curves(run_dir, task: str, out_path=None, initial: dict | None = None,
                title: str | None = None, best_epoch: int | None = None) -> Path | None:
    """Draws :func:`curves_figure` of a run directory's logs to ``out_path`` (default
    ``RUN_DIR/curves.png``). Returns the PNG path, or None when nothing was logged per
    epoch."""
    logs = read_logs(run_dir)
    if not any(k.startswith(("train/", "val/")) for k in logs):
        return None
    fig = curves_figure(logs, task, initial, title, best_epoch)
    out = Path(out_path) if out_path is not None else Path(run_dir) / "curves.png"
    return save_figure(fig, out)


def save_figure(fig, out) -> Path:
    """Writes a matplotlib figure as PNG ``out`` (temporary name, then renamed; an existing
    file is replaced) and closes it, whatever happens."""
    import matplotlib.pyplot as plt

    from ..atomic import atomic_output

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_output(out, force=True) as tmp:
            fig.savefig(tmp, dpi=100, format="png")
    finally:
        plt.close(fig)
    return out


def _positive(logs: dict, keys) -> bool:
    values = [v for k in keys if k in logs for v in logs[k].values()]
    return bool(values) and min(values) > 0 and max(values) / min(values) > 20
