"""A run's CSV logs (``logs/version_*/metrics.csv``), read into per-epoch values: what
bsp-train takes the best epoch's val metrics from and draws ``curves.png`` with
(:func:`bsp_fast.reporting.curves.plot_curves`), and what ``bsp-reproduce`` draws a
table's learning curves from."""
from __future__ import annotations

import csv
import re
from pathlib import Path

__all__ = ["read_logs"]


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
