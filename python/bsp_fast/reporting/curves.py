"""``curves.png``: loss and the task's main metrics per epoch, from a run's logs as
:func:`bsp_fast.training.logs.read_logs` reads them; and :func:`save_figure`, which every
figure of the package is written with.

The metrics drawn are the ones handed over (the task's ``curve_metrics``), in the unit of
the tables (PCK in %, errors in mm); a dotted line marks the best epoch (the checkpoint
that was tested) and the epoch axis has whole-number ticks.
"""
from __future__ import annotations

import math
from pathlib import Path

__all__ = ["plot_curves", "curves_figure", "best_epoch_of", "save_figure"]


def best_epoch_of(logs: dict) -> int | None:
    """1-based epoch of the lowest logged val loss (what the best checkpoint monitors)."""
    val = {e: v for e, v in logs.get("val/loss", {}).items() if math.isfinite(v)}
    return min(val, key=val.get) + 1 if val else None


def curves_figure(logs: dict, metrics, initial: dict | None = None,
                  title: str | None = None, best_epoch: int | None = None):
    """The matplotlib figure of :func:`plot_curves`: train/val loss, and the val values of
    ``metrics`` (:class:`bsp_fast.metrics.spec.Metric`; those logged) in the tables'
    units (dashed: the trivial baseline's ``initial`` val metrics; dotted: ``best_epoch``,
    1-based, by default the epoch of the lowest val loss)."""
    from .._extras import require

    matplotlib = require("matplotlib", "bsp-train (curves.png)", extra="torch")
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    metrics = [m for m in metrics if f"val/{m.key}" in logs]
    best = best_epoch_of(logs) if best_epoch is None else best_epoch
    fig, axes = plt.subplots(1, 1 + bool(metrics), figsize=(11 if metrics else 6, 4),
                             squeeze=False)
    _loss_panel(axes[0, 0], logs, initial)
    if metrics:
        _metric_panel(axes[0, 1], logs, metrics, initial)
    _epoch_axes(axes[0], best, bool(initial))
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def _loss_panel(ax, logs: dict, initial: dict | None) -> None:
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


def _metric_panel(mx, logs: dict, metrics: list, initial: dict | None) -> None:
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


def _epoch_axes(axes, best: int | None, initial: bool) -> None:
    """The best epoch's dotted line, whole-number epoch ticks, grid and legends."""
    from matplotlib.ticker import MaxNLocator

    for i, a in enumerate(axes):
        if best is not None:
            a.axvline(best, ls=":", c="black", lw=1,
                      label=f"best epoch ({best})" if i == 0 else None)
        a.set_xlabel("epoch")
        a.xaxis.set_major_locator(MaxNLocator(integer=True))
        a.grid(alpha=0.3)
        a.legend(title="dashed: initial metrics" if i and initial else None)


def plot_curves(logs: dict, metrics, out_path, initial: dict | None = None,
                title: str | None = None, best_epoch: int | None = None) -> Path | None:
    """Draws :func:`curves_figure` of a run's ``logs`` to ``out_path`` (a run's
    ``curves.png``). Returns the PNG path, or None when nothing was logged per epoch."""
    if not any(k.startswith(("train/", "val/")) for k in logs):
        return None
    return save_figure(curves_figure(logs, metrics, initial, title, best_epoch), out_path)


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
