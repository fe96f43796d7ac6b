"""experiments/budget_plateau.py on hand-made run logs: the best val loss's gain over the
last quarter of updates, by hand; a row whose seeds still improve gets twice its cap."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def _load():
    spec = importlib.util.spec_from_file_location("budget_plateau",
                                                  ROOT / "experiments" / "budget_plateau.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _run(path: Path, losses: list, steps_per_epoch: int = 10, cap: int = 40, epochs: int = 4):
    (path / "logs" / "version_0").mkdir(parents=True)
    lines = ["epoch,step,val/loss"]
    for e, v in enumerate(losses):
        lines.append(f"{e},{(e + 1) * steps_per_epoch - 1},{v}")
    (path / "logs" / "version_0" / "metrics.csv").write_text("\n".join(lines) + "\n")
    (path / "config.yaml").write_text(yaml.safe_dump({"max_steps": cap, "epochs": epochs}))
    (path / "metrics.json").write_text("{}")


def test_gain_in_the_tail_by_hand(tmp_path, capsys):
    bp = _load()
    # 4 epochs x 10 updates: the last quarter is epoch 4 (updates 31-40); the best before
    # it is 0.5 (epoch 3), the best overall 0.4: gain (0.5 - 0.4) / 0.5 = 20 %
    _run(tmp_path / "t" / "still" / "seed-1", [1.0, 0.6, 0.5, 0.4])
    _run(tmp_path / "t" / "still" / "seed-2", [1.0, 0.6, 0.5, 0.499])
    # flat: the best (0.3, epoch 2) is before the tail: gain 0
    _run(tmp_path / "t" / "flat" / "seed-1", [0.5, 0.3, 0.31, 0.32])
    r = bp.run_plateau(tmp_path / "t" / "still" / "seed-1", 0.25)
    assert r["best_epoch"] == 4 and r["epochs"] == 4 and r["updates"] == 40
    assert abs(r["gain_in_tail"] - 0.2) < 1e-12 and not r["stopped_early"]
    out = tmp_path / "rows.json"
    assert bp.main([str(tmp_path / "t"), "--json", str(out)]) == 0
    rows = {r["row"]: r for r in json.loads(out.read_text())}
    assert rows["still"]["plateau"] is False and rows["still"]["proposed_max_steps"] == 80
    assert rows["flat"]["plateau"] is True and rows["flat"]["proposed_max_steps"] == 40
    assert "| still | 2 | 4/4, 4/4 | 40 (40) | 20.0 %, 0.2 % | no | 80 |" in capsys.readouterr().out
