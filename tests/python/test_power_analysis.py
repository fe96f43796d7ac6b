"""Power before runs (#56, item 5, experiments/power_analysis.py): the sizes by hand, the
registered ``power:`` blocks are what the command computes from the published sums, and
the block stays outside the protocol hash."""
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _power():
    spec = importlib.util.spec_from_file_location(
        "power_analysis", ROOT / "experiments" / "power_analysis.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_sizes_by_hand():
    P = _power()
    c = {"seed": 0.01, "recording": 0.04, "interaction": 0.02}
    # SE 0.05 at 5 seeds: 0.0025 - 0.01 / 5 = 0.0005 left for (0.04 + 0.02 / 5) / R: 88
    assert P.needs(c, 0.05, S=5) == 88
    # at 20 recordings: 0.0025 - 0.04 / 20 = 0.0005 for (0.01 + 0.02 / 20) / S: 22
    assert P.needs(c, 0.05, R=20) == 22
    assert P.needs(c, 0.04, S=5) is None  # the seeds alone take more than 0.04^2
    assert P.needs({"seed": 0.0, "recording": 0.0, "interaction": 0.0}, 0.1, S=5) == 10


def test_registered_power_is_what_the_command_computes(monkeypatch):
    monkeypatch.chdir(ROOT)
    from bsp_fast.reproduction import readme as RM
    from bsp_fast.reproduction.protocol import table_hash
    from bsp_fast.reproduction.table_files import load_table
    import json

    P = _power()
    tab = load_table("autoencoder")
    got = P.table_power(tab, RM.load_published(ROOT / "docs/results/autoencoder-quick.json"))
    block = tab["power"]
    assert block["level"] == got["level"] == pytest.approx(0.05 / 4)
    assert block["findings"] == got["findings"]
    # the block is a record about the protocol, outside its hash: the published runs'
    # hash is the table file's
    doc = json.loads((ROOT / "docs/results/autoencoder-quick.json").read_text())
    assert table_hash(tab["path"]) == doc["protocol"]["hash"]
