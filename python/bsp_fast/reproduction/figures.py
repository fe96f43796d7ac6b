"""Figures a table file declares (``figures:``), drawn by ``bsp-reproduce`` into the
table's run folder (``OUT/TABLE-BUDGET/FILE.png``) from the rows' results: one metric
against a row setting (``x: mjp`` or ``x: noise``), one line per declared group of rows,
the mean over seeds with a band of ± one sample standard deviation and every seed's value
as a dot. See docs/reproduce.md ("Figures") and docs/figures/README.md.

A figure entry::

    figures:
      - file: f1_vs_mjp.png
        metric: f1
        x: mjp
        title: "F1 against MJP"
        lines:
          - {label: "LSTM, σ 0", rows: [lstm-s0-m0, lstm-s0-m0.3]}
"""
from __future__ import annotations

import math
import re
from pathlib import Path

__all__ = ["FIGURE_KEYS", "X_SETTINGS", "check_figures", "figure_series", "draw_figures"]

FIGURE_KEYS = ("file", "metric", "x", "title", "lines")
#: row settings a figure may put on its x axis (as the runs recorded them)
X_SETTINGS = ("mjp", "noise")


def check_figures(tab: dict) -> None:
    """ValueError naming the table file and the figure for a bad ``figures`` entry."""
    where = tab.get("path", tab.get("table"))
    figs = tab.get("figures", [])
    if not isinstance(figs, list):
        raise ValueError(f"{where}: figures must be a list, got {type(figs).__name__}")
    names = {r["name"] for r in tab["rows"]}
    files = set()
    for i, fig in enumerate(figs):
        what = f"{where}: figure {i + 1}"
        if not isinstance(fig, dict) or set(fig) - set(FIGURE_KEYS):
            raise ValueError(f"{what}: a mapping with keys from {list(FIGURE_KEYS)}, got {fig!r}")
        file = fig.get("file")
        if not isinstance(file, str) or not re.fullmatch(r"[-_.A-Za-z0-9]+\.png", file):
            raise ValueError(f"{what}: file {file!r} must be a plain name ending in .png")
        if file in files or file == "curves.png":
            raise ValueError(f"{what}: file {file!r} is already written for this table")
        files.add(file)
        if fig.get("metric") not in tab["metrics"]:
            raise ValueError(f"{what}: metric {fig.get('metric')!r} is not one of "
                             f"{list(tab['metrics'])}")
        if fig.get("x") not in X_SETTINGS:
            raise ValueError(f"{what}: x {fig.get('x')!r}; allowed: {list(X_SETTINGS)}")
        lines = fig.get("lines")
        if not isinstance(lines, list) or not lines:
            raise ValueError(f"{what}: lines must be a non-empty list of {{label, rows}}")
        for line in lines:
            if not isinstance(line, dict) or not isinstance(line.get("label"), str) \
                    or not isinstance(line.get("rows"), list) or not line["rows"]:
                raise ValueError(f"{what}: a line is {{label: TEXT, rows: [ROW, ...]}}, "
                                 f"got {line!r}")
            bad = [r for r in line["rows"] if r not in names]
            if bad:
                raise ValueError(f"{what}: line {line['label']!r} names unknown row(s) {bad}")


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

    from ..training.curves import save_figure

    written = []
    n_seeds = len(res.get("seeds") or [1])
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
def _val_series(run_dir: Path, metric: str) -> dict:
    """``{optimiser updates: val metric}`` of one run, from the CSV logs as
    :func:`~bsp_fast.training.curves.read_logs` reads them (Lightning logs epoch-end values
    at the index of the epoch's last update, hence + 1)."""
    from ..training.curves import read_logs

    logs = read_logs(run_dir)
    steps = logs.get("step", {})
    return {int(steps[e]) + 1: v for e, v in logs.get(f"val/{metric}", {}).items()
            if e in steps}


def learning_curves(tab: dict, res: dict, path=None):
    """``curves.png`` of a table: the validation main metric (the table's first) against
    optimiser updates for every trained row, the mean over seeds and a band of ± one
    standard deviation. Returns the path, or None when nothing was logged."""
    import numpy as np

    metric = next(iter(tab["metrics"]))
    series = {}
    for name, r in res["results"].items():
        if r.get("source") != "test":
            continue
        # runs read from a published table (.restore) have no logs here
        runs = [_val_series(Path(s["run"]), metric) for s in r["seeds"].values() if s["run"]]
        steps = sorted({k for run in runs for k in run})
        if steps:
            vals = [[run[k] for run in runs if k in run] for k in steps]
            series[name] = (np.array(steps), np.array([np.mean(v) for v in vals]),
                            np.array([np.std(v) for v in vals]))
    if not series:
        return None
    from .._extras import require
    from ..training.curves import save_figure

    require("matplotlib", "bsp-reproduce's curves.png").use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, (x, mean, std) in series.items():
        line, = ax.plot(x, mean, marker=".", label=name)
        ax.fill_between(x, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    spec = tab["metrics"][metric]
    ax.set_xlabel("optimiser updates")
    ax.set_ylabel(f"val {spec['label']}")
    ax.grid(alpha=0.3)
    ax.legend(title=f"mean ± std over {len(res.get('seeds') or [1])} seed(s)")
    ax.set_title(f"{tab['table']} — budget {res['budget']}")
    fig.tight_layout()
    out = Path(path) if path is not None else Path(res["dir"]) / "curves.png"
    return save_figure(fig, out)
