"""The one value formatter of every table (runs, reproduced tables, breakdowns, the
results page), in a metric's declared format (:class:`bsp_fast.metrics.spec.Metric`'s
``fmt``)."""
from __future__ import annotations

__all__ = ["format_metric", "format_value"]


def format_metric(fmt: str, value, diff: bool = False, missing: str = "–") -> str:
    """``value`` in a metric's ``fmt`` (a format spec, or ``pct``: a fraction shown in %
    with one decimal), ``diff`` with a sign; ``missing`` for no value or NaN."""
    if value is None or (isinstance(value, float) and value != value):
        return missing
    if fmt == "pct":
        return f"{100 * value:+.1f}" if diff else f"{100 * value:.1f}"
    return format(value, ("+" if diff else "") + fmt)


def format_value(tab, metric, value, diff: bool = False) -> str:
    """A value of ``metric`` in ``tab``'s format (a table file's ``metrics``, whose formats
    are the task registry's; ``.3f`` for a metric the table does not name)."""
    return format_metric(tab["metrics"].get(metric, {}).get("format", ".3f"), value, diff)
