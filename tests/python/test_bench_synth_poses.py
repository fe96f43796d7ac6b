"""Smoke tests of issue 59's benchmarks on tiny inputs: benchmarks/bench_synth_poses.py
(generation against write_csv of its table, conversion against wc -l and read_csv) and
benchmarks/bench_convert.py's conversion table with its wc -l and read_csv columns."""
from __future__ import annotations

import importlib
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture()
def benchmarks(monkeypatch):
    # Spawned synth workers import nothing from here; bench_convert imports bench_csv by name.
    monkeypatch.syspath_prepend(str(BENCH))
    return lambda name: importlib.import_module(name)


def test_bench_synth_poses_smoke(benchmarks, capsys, tmp_path):
    bench = benchmarks("bench_synth_poses")
    assert bench.main(["--preset", "sample", "--clips", "2", "--workers", "1", "--convert",
                       "--repeat", "1", "--dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "| generate (poses only) |" in out and "| write_csv of its table |" in out
    assert "write_csv's file byte-identical to data.csv: True" in out
    for step in ("wc -l", "read_csv", "bsp-convert"):
        assert f"| {step} |" in out
    assert list(tmp_path.iterdir()) == []  # its work folder is removed


@pytest.mark.filterwarnings("ignore::UserWarning")  # a tiny file: small splits
def test_bench_convert_reports_wc_and_read_csv(benchmarks, capsys, tmp_path):
    bench = benchmarks("bench_convert")
    assert bench.main(["--rows", "400", "--convert-only", "--data", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    row = [line for line in out.splitlines() if line.startswith("| uncompressed (default) |")]
    assert len(row) == 1 and row[0].count("×") == 2
