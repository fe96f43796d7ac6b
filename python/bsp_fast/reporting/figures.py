"""Figures of a reproduced table, drawn into its run folder from the rows' results: the
figures a table file declares (``figures:``, checked by
:func:`bsp_fast.reproduction.table_files.check_figures`; ``OUT/TABLE-BUDGET/FILE.png``): one
metric against a row setting (``x: mjp`` or ``x: noise``), one line per declared group of
rows, the mean over seeds with a band of ± one sample standard deviation and every seed's
value as a dot; and the table's learning curves (``curves.png``). See docs/reproduce.md
("Figures") and docs/figures/README.md.
"""
from __future__ import annotations

import math
from pathlib import Path

__all__ = ["figure_series", "draw_figures", "learning_curves"]


def _seed_values(r: dict, metric: str) -> list:
    """The values of ``metric`` of one row's result: one per seed, or the single run's
    of a results.json written before the runner gave every row its ``seeds`` (#35)."""
    key = "initial" if r.get("source") == "initial" else "metrics"
    if "seeds" in r:
        vals = [s[key].get(metric) for s in r["seeds"].values()]
    else:
        vals = [r.get(key, {}).get(metric)]
    return [float(v) for v in vals if v is not None and math.isfinite(v)]


def figure_series(fig: dict, res: dict) -> list:
    """``[(label, [(x, mean, std, values), ...]), ...]``: each line's points sorted by x,
    from the rows that ran (rows not run, or with a per-joint setting, are left out);
    ``std`` is the sample standard deviation over seeds (0 for one value)."""
    import numpy as np

    out = []
    for line in fig["lines"]:
        points = []
        for name in line["rows"]:
            r = res["results"].get(name)
            if r is None:
                continue
            x = r.get(fig["x"])
            x = 0.0 if x is None else x
            vals = _seed_values(r, fig["metric"])
            if isinstance(x, list) or not vals:
                continue
            std = float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0
            points.append((float(x), float(np.mean(vals)), std, vals))
        if points:
            out.append((line["label"], sorted(points, key=lambda p: p[0])))
    return out


def draw_figures(tab: dict, res: dict, out_dir=None) -> list:
    """Draws every figure of ``tab`` from ``res`` (``bsp-reproduce``'s results, one run or
    ``--seeds``) into ``out_dir`` (default ``res["dir"]``); returns the paths written
    (a figure with no row run is skipped)."""
    figs = tab.get("figures") or []
    if not figs:
        return []
    from .._extras import require

    require("matplotlib", "bsp-reproduce's figures").use("Agg", force=True)
    import matplotlib.pyplot as plt

    from .curves import save_figure

    written = []
    n_seeds = len(res["seeds"])
    for fig in figs:
        series = figure_series(fig, res)
        if not series:
            continue
        f, ax = plt.subplots(figsize=(7, 4.5))
        for label, points in series:
            x = [p[0] for p in points]
            mean = [p[1] for p in points]
            std = [p[2] for p in points]
            line, = ax.plot(x, mean, marker="o", label=label)
            ax.fill_between(x, [m - s for m, s in zip(mean, std)],
                            [m + s for m, s in zip(mean, std)], color=line.get_color(),
                            alpha=0.2, lw=0)
            for xi, _, _, vals in points:
                ax.scatter([xi] * len(vals), vals, s=8, color=line.get_color(), alpha=0.6)
        spec = tab["metrics"][fig["metric"]]
        values = [v for _, pts in series for p in pts for v in p[3]]
        if min(values) >= 0.0 and max(values) <= 1.0:  # a fraction: its whole range
            ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel({"mjp": "missing-joint probability (MJP)",
                       "noise": "input noise σ (px)"}[fig["x"]])
        ax.set_ylabel(f"test {spec['label']}")
        ax.grid(alpha=0.3)
        ax.legend(title=f"mean ± std over {n_seeds} seed(s); dots: seeds", fontsize=8)
        ax.set_title(fig.get("title") or f"{tab['table']}: {spec['label']}", fontsize=10)
        f.text(0.99, 0.01, f"budget {res['budget']}", ha="right", va="bottom", fontsize=7,
               color="grey")
        f.tight_layout()
        out = Path(out_dir if out_dir is not None else res["dir"]) / fig["file"]
        written.append(save_figure(f, out))
    return written


# ---------------------------------------------------------------------- learning curves
def learning_curves(tab: dict, res: dict, runs: dict, path=None):
    """``curves.png`` of a table: the validation main metric (the table's first) against
    optimiser updates for every trained row, the mean over seeds and a band of ± one
    standard deviation. ``runs``: ``{row: [{optimiser updates: val metric} per run]}``
    (:func:`bsp_fast.reproduction.report.val_series`). Returns the path, or None when
    nothing was logged."""
    import numpy as np

    series = {}
    for name, per_run in runs.items():
        steps = sorted({k for run in per_run for k in run})
        if steps:
            vals = [[run[k] for run in per_run if k in run] for k in steps]
            series[name] = (np.array(steps), np.array([np.mean(v) for v in vals]),
                            np.array([np.std(v) for v in vals]))
    if not series:
        return None
    from .._extras import require
    from .curves import save_figure

    require("matplotlib", "bsp-reproduce's curves.png").use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, (x, mean, std) in series.items():
        line, = ax.plot(x, mean, marker=".", label=name)
        ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    spec = tab["metrics"][next(iter(tab["metrics"]))]
    ax.set_xlabel("optimiser updates")
    ax.set_ylabel(f"val {spec['label']}")
    ax.grid(alpha=0.3)
    ax.legend(title=f"mean ± std over {len(res.get('seeds') or [1])} seed(s)")
    ax.set_title(f"{tab['table']} — budget {res['budget']}")
    fig.tight_layout()
    out = Path(path) if path is not None else Path(res["dir"]) / "curves.png"
    return save_figure(fig, out)
