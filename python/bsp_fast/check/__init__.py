"""``bsp-check``: find what is wrong with a CARLA-BSP dataset, and write a cleaned copy.

``check_dataset(path)`` returns the report (findings, per-recording table, statistics);
``fix_dataset(path, out_dir)`` checks and writes a copy without the broken or invisible
recordings and the duplicate or fully occluded rows, every kept byte unchanged. See
docs/check.md.
"""
from __future__ import annotations

from .core import BREAKING, KINDS, check_dataset
from .fix import fix_dataset
from .report import format_report, to_json

__all__ = ["check_dataset", "fix_dataset", "format_report", "to_json", "KINDS", "BREAKING"]
