"""bsp-reproduce is its own package on top of training, with one runner and one report
writer; no old import path is kept alive (a 0.1 package has no users of them to keep)."""
import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PKG = ROOT / "python" / "bsp_fast"


def test_nothing_in_training_imports_reproduction():
    for path in (PKG / "training").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.ImportFrom):
                names = [("." * node.level) + (node.module or "")]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for n in names:
                assert "reproduction" not in n, f"{path}:{node.lineno} imports {n}"


def test_training_holds_one_run_and_tasks_only_declarations():
    tasks = (PKG / "training" / "tasks").glob("*.py")
    for path in tasks:  # declarations: nothing above tasks/, no torch or Lightning on import
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):  # training's modules are level 2 from here
                assert node.level != 2, f"{path}:{node.lineno} imports from training/"
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                mods = [a.name for a in node.names] if isinstance(node, ast.Import) \
                    else [node.module or ""]
                assert not any(m.split(".")[0] in ("torch", "lightning") for m in mods), path


@pytest.mark.parametrize("old", ["bsp_fast.training.reproduce", "bsp_fast.training.seeds",
                                 "bsp_fast.training.evidence", "bsp_fast.training.breakdown",
                                 "bsp_fast.training.tasks.module"])
def test_no_shims_for_old_import_paths(old):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)


def test_smoke_tables_carry_the_banner_and_others_do_not(tmp_path):
    from bsp_fast.reproduction import load_table
    from bsp_fast.reporting.reproduced import SMOKE_BANNER, format_table

    tab = load_table("autoencoder")
    for budget, seeds in (("smoke", [1]), ("smoke", [1, 2]), ("quick", [1])):
        res = {"table": tab["table"], "budget": budget, "dir": str(tmp_path),
               "seeds": seeds, "split_seeds": False, "results": {}}
        text = format_table(tab, res, [])
        assert (SMOKE_BANNER in text) == (budget == "smoke"), (budget, seeds)


def test_a_new_bsp_train_option_reaches_eval_predict_and_reproduce(monkeypatch, capsys):
    """One declaration (training/config.py): bsp-eval, bsp-predict and bsp-reproduce build
    their overrides from bsp-train's options, with the same help and converter."""
    from bsp_fast.reproduction import cli as reproduce_cli
    from bsp_fast.training import config as C, evaluate, predict
    from bsp_fast.training.overrides import given_overrides

    knob = C.Option("frobnicate_level", "int", 0, "how hard to frobnicate (a test option)",
                    "training", minimum=0, metavar="N", scoring=True)
    monkeypatch.setattr(C, "OPTIONS", C.OPTIONS + (knob,))
    for main in (evaluate.main, predict.main):
        with pytest.raises(SystemExit):
            main(["--help"])
        out = capsys.readouterr().out
        assert "--frobnicate-level N" in out and "how hard to frobnicate" in out, main
    # parsed with the option's own converter and message
    p = evaluate._parser()
    ns = p.parse_args(["run", "--frobnicate-level", "3"])
    assert given_overrides(ns, ns.overrides) == {"frobnicate_level": 3}
    with pytest.raises(SystemExit):
        p.parse_args(["run", "--frobnicate-level", "-1"])
    assert "frobnicate_level must be >= 0" in capsys.readouterr().err
    # a scoring option absent from the line is no override (the run's value stays)
    assert given_overrides(p.parse_args(["run"]), ns.overrides) == {}
    # bsp-reproduce takes every option but the run's identity, for every row, as --set
    assert reproduce_cli.parse_set(["epochs=3", "frobnicate-level=2"]) == {
        "epochs": 3, "frobnicate_level": 2}
    with pytest.raises(C.ConfigError, match="did you mean 'epochs'"):
        reproduce_cli.parse_set(["epohcs=1"])
    for name in ("model", "resume", "task", "seed"):
        with pytest.raises(C.ConfigError, match="not a per-row override"):
            reproduce_cli.parse_set([f"{name}=1"])
