"""The house's third pass (#35): bsp-reproduce is its own package on top of training, with
one runner and one report writer; the old import paths keep working for one release."""
import ast
import warnings
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
    files = sorted(p.name for p in (PKG / "training").glob("*.py"))
    assert len(files) <= 20, files
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


@pytest.mark.parametrize("old,new,name", [
    ("bsp_fast.training.reproduce", "bsp_fast.reproduction", "main"),
    ("bsp_fast.training.seeds", "bsp_fast.reproduction.runner", "reproduce_seeds"),
    ("bsp_fast.training.seeds", "bsp_fast.reproduction.figures", "learning_curves"),
    ("bsp_fast.training.evidence", "bsp_fast.reproduction.evidence", "summarise"),
    ("bsp_fast.training.evidence", "bsp_fast.reproduction.report", "format_table"),
    ("bsp_fast.training.table_files", "bsp_fast.reproduction.table_files", "load_table"),
    ("bsp_fast.training.breakdown", "bsp_fast.training.per_recording", "FILE"),
    ("bsp_fast.training.tasks.module", "bsp_fast.training.module", "LiftingTask"),
])
def test_old_import_paths_still_work_and_say_where_things_moved(old, new, name):
    import importlib
    import sys

    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mod = importlib.import_module(old)
        got = getattr(mod, name)
    assert got is getattr(importlib.import_module(new), name)
    assert any(issubclass(w.category, DeprecationWarning) and new in str(w.message)
               for w in caught)
    with pytest.raises(AttributeError, match="no attribute"):
        getattr(mod, "no_such_name")


def test_the_lightning_modules_moved_out_of_the_task_registry():
    from bsp_fast.training import module, tasks

    with pytest.warns(DeprecationWarning, match="bsp_fast.training.module.LiftingTask"):
        assert tasks.LiftingTask is module.LiftingTask
    with pytest.raises(AttributeError):
        tasks.NoSuchTask  # noqa: B018


def test_smoke_tables_carry_the_banner_and_others_do_not(tmp_path):
    from bsp_fast.reproduction import load_table
    from bsp_fast.reproduction.report import SMOKE_BANNER, format_table

    tab = load_table("autoencoder")
    for budget, seeds in (("smoke", None), ("smoke", [1, 2]), ("quick", None)):
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
    for main in (evaluate.main, predict.main, reproduce_cli.main):
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
    # bsp-reproduce takes every option but the run's identity, for every row
    rp = reproduce_cli.build_parser()
    ns = rp.parse_args(["lifting", "--data", "d", "--epochs", "3", "--frobnicate-level", "2"])
    assert given_overrides(ns, ns.overrides) == {"epochs": 3, "frobnicate_level": 2}
    flags = {f for a in rp._actions for f in a.option_strings}
    assert not flags & {"--model", "--resume", "--task", "--seed", "--hp"}
