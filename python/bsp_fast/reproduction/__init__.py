"""Reproduction of the report's tables (``bsp-reproduce``): table files
(:mod:`.table_files`), the one runner for one or N seeds (:mod:`.runner`), the statistics
(:mod:`.evidence`, over :mod:`bsp_fast.metrics.uncertainty`), findings marked from single
runs (:mod:`.findings`), the one report writer (:mod:`.report`, which renders through
:mod:`bsp_fast.reporting`), the cost and breakdown of the rows and the command line
(:mod:`.cli`). It drives :mod:`bsp_fast.training` (one run each); nothing in ``training``
imports it. See docs/reproduce.md.
"""
from __future__ import annotations

from .cli import build_parser, main
from .findings import NA, NO, YES, evaluate_findings
from .report import format_report, write_report
from .runner import run_table, seed_list
from .table_files import (BUDGETS, KINDS, RELATIONS, TABLES, experiments_dir,
                          experiments_dirs, load_table, row_options, table_names)
from ..training.tasks.classification import constant_f1

__all__ = ["TABLES", "BUDGETS", "KINDS", "RELATIONS", "YES", "NO", "NA", "experiments_dir",
           "experiments_dirs", "load_table", "row_options", "table_names", "run_table", "seed_list", "evaluate_findings", "format_report",
           "write_report", "main", "build_parser", "constant_f1"]
