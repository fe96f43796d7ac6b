"""Where bsp-reproduce finds its table files: the installed package's copy (the wheel's
layout, run from another directory), or a user's own table file given by path."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _wheel_packages() -> dict:
    """pyproject's tool.scikit-build wheel.packages as {wheel path: source folder}."""
    tomllib = pytest.importorskip("tomllib")
    skb = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["scikit-build"]
    packages = skb["wheel"]["packages"]
    if isinstance(packages, list):  # a list keeps each folder's name
        return {Path(p).name: p for p in packages}
    return dict(packages)


def test_installed_layout_finds_the_tables_outside_the_source_tree(tmp_path):
    """The package as the wheel lays it out (from pyproject's mapping), run from another
    directory: bsp-reproduce finds its tables there, not in a source checkout."""
    site = tmp_path / "site"
    for dest, src in _wheel_packages().items():
        shutil.copytree(ROOT / src, site / dest, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__"))
    elsewhere = tmp_path / "somewhere" / "else"
    elsewhere.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(site))  # _core: the installed one (_native.py)
    code = ("from bsp_fast.reproduction import load_table, TABLES\n"
            "for t in TABLES:\n    print(load_table(t)['path'])\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=elsewhere, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    from bsp_fast.reproduction import TABLES

    assert r.stdout.split() == [str(site / "bsp_fast" / "experiments" / f"{t}.yaml")
                                for t in TABLES]
    for t in TABLES:  # the shipped copy is the source of truth's
        assert (site / "bsp_fast" / "experiments" / f"{t}.yaml").read_bytes() == \
            (ROOT / "experiments" / f"{t}.yaml").read_bytes()
    # and the command runs there (--dry-run: the per-row configs of the smoke budget)
    (tmp_path / "ds").mkdir(exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "reproduce", "autoencoder", "--data",
                        str(tmp_path / "ds"), "--budget", "smoke", "--dry-run", "--out", "runs"],
                       cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "bsp-train --config runs/autoencoder-smoke/configs/" in r.stdout
    assert (elsewhere / "runs" / "autoencoder-smoke" / "configs").is_dir()


def test_reproduce_reads_a_users_own_table_file(tmp_path, capsys):
    from bsp_fast.reproduction import main

    mine = tmp_path / "mine.yaml"
    text = (ROOT / "experiments" / "autoencoder.yaml").read_text()
    mine.write_text(text.replace("table: autoencoder", "table: my_autoencoder", 1))
    assert "table: my_autoencoder" in mine.read_text()
    out = tmp_path / "runs"
    (tmp_path / "ds").mkdir()
    assert main([str(mine), "--data", str(tmp_path / "ds"), "--budget", "smoke",
                 "--dry-run", "--out", str(out)]) == 0
    assert (out / "my_autoencoder-smoke" / "configs").is_dir()
    assert "bsp-train --config" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:  # one TABLE: a name or a path
        main(["autoencoder", str(mine), "--data", "x"])
    assert e.value.code == 2
    with pytest.raises(SystemExit):
        main(["--data", "x"])
    assert "the following arguments are required: TABLE" in capsys.readouterr().err
    assert main([str(tmp_path / "nope.yaml"), "--data", "x", "--dry-run"]) == 2
    assert "nope.yaml: no such table file" in capsys.readouterr().err
