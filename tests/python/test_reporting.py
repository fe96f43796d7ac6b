"""bsp_fast.reporting, the one rendering layer (#55, item 1): it stands below training/
and reproduction/ (imports neither, not even lazily) and renders what it is handed."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

from bsp_fast.metrics.spec import NORMALISER_FALLBACK
from bsp_fast.reporting.run_tables import initial_text, scored_text
from bsp_fast.reporting.values import format_metric, format_value

PKG = Path(__file__).resolve().parents[2] / "python" / "bsp_fast"


def _imports(path: Path) -> set:
    """Every module a file imports, at the top or inside a function, made absolute."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = ["bsp_fast", "reporting"][:2 - node.level + 1] if node.level else []
            out.add(".".join(base + ([node.module] if node.module else [])))
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_reporting_imports_neither_training_nor_reproduction():
    files = sorted((PKG / "reporting").glob("*.py"))
    assert len(files) >= 8
    for f in files:
        up = [m for m in _imports(f) if m.startswith(("bsp_fast.training",
                                                      "bsp_fast.reproduction"))]
        assert not up, (f.name, up)


def test_importing_the_renderers_loads_no_training_code():
    code = ("import sys, bsp_fast.reporting.reproduced, bsp_fast.reporting.breakdown, "
            "bsp_fast.reporting.results_page, bsp_fast.reporting.run_tables, "
            "bsp_fast.reporting.figures, bsp_fast.reporting.curves, bsp_fast.reporting.findings, "
            "bsp_fast.reporting.estimate; "
            "print(sorted(m for m in sys.modules if m.startswith(('bsp_fast.training', "
            "'bsp_fast.reproduction', 'torch', 'matplotlib'))))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "[]"


def test_one_value_formatter():
    assert format_metric("pct", 0.4567) == "45.7" and format_metric("pct", 0.1, True) == "+10.0"
    assert format_metric(".2f", float("nan")) == "–"
    assert format_metric(".3f", None, missing="—") == "—"
    tab = {"metrics": {"mpjpe_mm": {"format": ".2f"}}}
    assert format_value(tab, "mpjpe_mm", 51.234) == "51.23"
    assert format_value(tab, "other", 0.5) == "0.500"  # not the table's: .3f


def test_scored_text_lists_the_metrics_and_explains_the_fallback():
    res = SimpleNamespace(task="lifting", model="lstm", split="test", checkpoint="r/best.ckpt",
                          clips=12, recordings=3,
                          metrics={"mpjpe_mm": 51.5, NORMALISER_FALLBACK.key: 0.25})
    lines = scored_text(res, limit_batches=2).splitlines()
    assert lines[0] == "lifting / lstm: test metrics of r/best.ckpt"
    assert lines[1] == "  scored 12 clips of 3 recordings (--limit-batches 2)"
    assert any(ln.split() == ["mpjpe_mm", "51.5"] for ln in lines)
    assert lines[-1].startswith("  (")


def test_initial_text_is_one_line_per_split_without_the_fallback_at_zero():
    initial = {"baseline": "identity", "val": {"mpjpe_mm": 80.12345, NORMALISER_FALLBACK.key: 0.0},
               "test": {"mpjpe_mm": 81.0, "pa_mpjpe_mm": None}}
    assert initial_text(initial).splitlines() == [
        "initial metrics (identity, before training):", "  val: mpjpe_mm 80.12",
        "  test: mpjpe_mm 81"]


def test_a_tables_load_is_said_from_its_runs_or_said_missing():
    from bsp_fast.reporting.results_page import _load_sentence

    runs = [("a", {"seconds": {"fit": 60.0, "load": [1.5, 3.25]}}),
            ("b", {"seconds": {"fit": 60.0, "load": [0.7, 2.0]}}),
            ("b", {"seconds": {"fit": 60.0}})]
    assert _load_sentence(runs) == ("Load (1-min average at each run's fit start and end): "
                                    "0.7-3.2; not recorded for 1 of 3 runs.")
    assert _load_sentence(runs[:2]).endswith(": 0.7-3.2.")
    assert _load_sentence(runs[2:]).startswith("Load: not recorded")
