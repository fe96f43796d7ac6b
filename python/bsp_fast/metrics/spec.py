"""What one scored value is, beside its number: ``Metric`` (its key in metrics.json, label,
unit, direction and table format) and the normaliser fallback share every 2D-input task
scores. The task registry (``bsp_fast.training.tasks``) declares its metrics with it and
the renderers (``bsp_fast.reporting``) read it; it lives here, below both, so that the
renderers need nothing from ``training`` to label and format a value. No torch.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Metric", "UNIT_SUFFIX", "NORMALISER_FALLBACK"]

#: Table/curve label suffix of a metric's display unit.
UNIT_SUFFIX = {"mm": " (mm)", "mm/frame": " (mm/frame)", "%": " (%)", "": ""}


@dataclass(frozen=True)
class Metric:
    """One scored value: ``key`` in metrics.json, ``label``, ``unit`` (``mm``, ``mm per
    frame`` or ``fraction``), ``better`` (``higher``, ``lower`` or ``none``) and ``fmt``, its table
    format (a format spec, or ``pct``: a fraction shown in %)."""
    key: str
    label: str
    unit: str
    better: str
    fmt: str

    @property
    def percent(self) -> bool:
        return self.fmt == "pct"

    @property
    def display_unit(self) -> str:
        """``%`` for fractions shown in %, ``mm``, ``mm/frame``, or ``""``."""
        if self.percent:
            return "%"
        return {"mm": "mm", "mm per frame": "mm/frame"}.get(self.unit, "")

    @property
    def header(self) -> str:
        """Label with its display unit, e.g. ``PCK@0.05 (%)``, ``MPJPE (mm)``."""
        return self.label + UNIT_SUFFIX[self.display_unit]

    def display(self, value: float) -> float:
        """``value`` in the display unit (fractions shown in % times 100)."""
        return 100.0 * value if self.percent else value


#: Share of input frames whose hips-neck normaliser fell back to the joint bbox (hips or
#: neck missing, or coinciding): scored by every 2D-input task (``normaliser_fallback`` in
#: the batch), logged as ``train/``, ``val/`` and ``test/normaliser_fallback``.
NORMALISER_FALLBACK = Metric("normaliser_fallback", "normaliser fallback", "fraction", "none",
                             "pct")
