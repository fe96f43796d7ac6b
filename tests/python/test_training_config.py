"""bsp-train options: YAML/CLI parsing and precedence, run directories, tables, curves
(no training here; see test_training.py for the end-to-end runs)."""
import json
import os

import pytest

from bsp_fast.training import config as C
from bsp_fast.training.runs import RunDirectory, RunError, resolve_checkpoint
from bsp_fast.reporting.run_tables import runs_table as render_runs
from bsp_fast.training.runs import read_finished
from bsp_fast.training.tasks import TABLE_COLUMNS


def runs_table(runs, fmt: str = "markdown", split: str = "test") -> str:
    """What ``bsp-eval --table`` prints: the runs read, then rendered."""
    return render_runs(read_finished(runs, split), TABLE_COLUMNS, fmt, split)


def test_hp_values_use_yaml_syntax():
    assert C.parse_hp(["hidden=32", "dropout=0.5", "pe=true", "name=abc", "dims=[1, 2]"]) == {
        "hidden": 32, "dropout": 0.5, "pe": True, "name": "abc", "dims": [1, 2]}
    assert C.parse_hp({"num-layers": 2}) == {"num_layers": 2}
    with pytest.raises(C.ConfigError, match="KEY=VALUE"):
        C.parse_hp(["hidden"])


def test_mjp_takes_one_value_or_26():
    opt = C.normalise({"mjp": "0.2944"})
    assert opt["mjp"] == pytest.approx(0.2944)
    per_joint = ",".join(["0.1"] * 26)
    assert C.normalise({"mjp": per_joint})["mjp"] == [0.1] * 26
    with pytest.raises(C.ConfigError, match="one value or 26"):
        C.normalise({"mjp": "0.1,0.2"})
    with pytest.raises(C.ConfigError, match=r"\[0, 1\]"):
        C.normalise({"mjp": 1.5})


def test_option_checks_list_the_allowed_values():
    with pytest.raises(C.ConfigError, match="unknown option 'epochz' \\(did you mean 'epochs'\\?\\); allowed: task, model"):
        C.normalise({"epochz": 3})
    with pytest.raises(C.ConfigError, match=r"precision must be one of \['auto', '32'"):
        C.normalise({"precision": "8"})
    with pytest.raises(C.ConfigError, match="epochs must be >= 1"):
        C.normalise({"epochs": 0})
    with pytest.raises(C.ConfigError, match="batch_size expects an integer"):
        C.normalise({"batch-size": 2.5})
    assert C.normalise({"devices": "0,1"})["devices"] == [0, 1]
    assert C.normalise({"devices": "2"})["devices"] == 2


def test_yaml_config_is_safe_and_checked(tmp_path):
    good = tmp_path / "run.yaml"
    good.write_text("task: lifting\nbatch-size: 64\nhp: {hidden: 8}\nmjp: 0.1\n")
    assert C.read_yaml(good) == {"task": "lifting", "batch_size": 64, "hp": {"hidden": 8},
                                 "mjp": 0.1}
    unsafe = tmp_path / "unsafe.yaml"
    unsafe.write_text("epochs: !!python/object/apply:os.system ['echo hi']\n")
    with pytest.raises(C.ConfigError, match="not valid YAML"):
        C.read_yaml(unsafe)
    with pytest.raises(C.ConfigError, match="no such file"):
        C.read_yaml(tmp_path / "missing.yaml")


def test_command_line_overrides_yaml_overrides_defaults(tmp_path):
    cli, config, show = C.parse_command_line(C.parser(), [
        "lifting", "--epochs", "5", "--no-augment", "--hp", "hidden=4", "--hp", "layers=1",
        "--mjp", "0.25", "--devices", "0,1", "--force"])
    assert cli == {"task": "lifting", "epochs": 5, "augment": False, "force": True,
                   "hp": {"hidden": 4, "layers": 1}, "mjp": 0.25, "devices": [0, 1]}
    assert (config, show) == (None, False)
    merged = C.defaults()
    merged.update({"epochs": 3, "batch_size": 16})  # as from --config
    merged.update(cli)
    assert (merged["epochs"], merged["batch_size"], merged["seed"]) == (5, 16, 22742)


def test_command_line_wins_over_config_wherever_it_stands(tmp_path):
    from bsp_fast.training.train import resolve_config

    run = tmp_path / "run.yaml"
    run.write_text("task: lifting\nmodel: baseline_3d\ndata: d.h5\nepochs: 3\n"
                   "batch-size: 16\nout: r\n")
    for argv in (["--epochs", "5", "--config", str(run)], ["--config", str(run), "--epochs", "5"],
                 [f"--config={run}", "--epochs=5", "--print-config"]):
        cli, config, show = C.parse_command_line(C.parser(), argv)
        assert (cli, config, show == ("--print-config" in argv)) == ({"epochs": 5}, str(run), True)
        cfg, resume = resolve_config(cli, config)
        assert (cfg["epochs"], cfg["batch_size"], cfg["model"], resume) == (5, 16, "baseline_3d", None)


def test_bad_command_line_values_keep_the_option_messages():
    import argparse

    p = C.parser()
    for argv, message in ((["--noise", "-1"], "noise must be >= 0.0, got -1.0"),
                          (["--epochs", "2.5"], "epochs expects an integer, got '2.5'"),
                          (["--precision", "8"], "precision must be one of ['auto', '32'"),
                          (["--mjp", "0.1,0.2"], "mjp takes one value or 26"),
                          (["--hp", "hidden"], "--hp expects KEY=VALUE, got 'hidden'"),
                          (["--devices", "x"], "devices must be 'auto', a count"),
                          (["lifting", "m", "extra"], "unrecognized arguments: extra"),
                          (["lifting", "m", "--epochz", "3"], "unrecognized arguments: --epochz 3")):
        with pytest.raises(argparse.ArgumentError) as info:
            C.parse_command_line(p, argv)
        assert message in str(info.value), argv
    with pytest.raises(argparse.ArgumentError, match="task must be one of"):
        C.parse_command_line(p, ["posing"])


def test_print_config_is_the_resolved_config_and_reads_back(tmp_path, capsys):
    from bsp_fast.training.train import main

    first = tmp_path / "a.yaml"
    first.write_text("task: lifting\nmodel: baseline_3d\nepochs: 3\nhp: {linear_size: 8}\n")
    argv = ["--config", str(first), "--data", "d.h5", "--out", "r", "--mjp", "0.5",
            "--print-config"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert text.startswith("# bsp-train resolved config (usable as --config)\n")
    printed = tmp_path / "printed.yaml"
    printed.write_text(text)
    cfg = C.read_yaml(printed)
    assert list(cfg) == [o.name for o in C.OPTIONS]
    assert (cfg["task"], cfg["epochs"], cfg["hp"], cfg["mjp"], cfg["data"], cfg["seed"]) == (
        "lifting", 3, {"linear_size": 8}, 0.5, "d.h5", 22742)
    assert main(["--config", str(printed), "--print-config"]) == 0
    assert capsys.readouterr().out == text  # a fixed point
    assert main(["--config", str(first), "--data", "d.h5", "--noise", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bsp-train: error: argument --noise") and len(err.splitlines()) == 1
    assert "noise must be >= 0.0, got -1.0" in err
    assert main(["pose_estimation", "pose_cnn", "--data", "d.h5", "--mjp", "0.1",
                 "--print-config"]) == 2
    assert "noise/mjp deform 2D joint inputs; pose_estimation reads images" in \
        capsys.readouterr().err


def test_run_directory_is_renamed_only_when_complete(tmp_path):
    final = tmp_path / "runs" / "a"
    with pytest.raises(ZeroDivisionError):
        with RunDirectory(final) as tmp:
            (tmp / "half-written.txt").write_text("x")
            1 / 0
    assert not final.exists() and os.listdir(tmp_path / "runs") == []
    with RunDirectory(final) as tmp:
        (tmp / "done.txt").write_text("1")
    assert (final / "done.txt").read_text() == "1"
    with pytest.raises(RunError, match="exists; pass --force") as info:
        RunDirectory(final)
    assert info.value.code == 3
    with RunDirectory(final, force=True) as tmp:
        (tmp / "done.txt").write_text("2")
    assert (final / "done.txt").read_text() == "2"
    assert sorted(os.listdir(tmp_path / "runs")) == ["a"]  # no temporary or old copies


def test_resolve_checkpoint_messages(tmp_path):
    with pytest.raises(RunError, match="no such run directory or checkpoint"):
        resolve_checkpoint(tmp_path / "nope")
    with pytest.raises(RunError, match="not a bsp-train run directory"):
        resolve_checkpoint(tmp_path)
    (tmp_path / "x.h5").write_text("")
    with pytest.raises(RunError, match="expected a run directory or a .ckpt"):
        resolve_checkpoint(tmp_path / "x.h5")


def _fake_run(root, name, task, model, test, initial, noise=0.0):
    run = root / name
    run.mkdir()
    (run / "config.yaml").write_text(f"task: {task}\nmodel: {model}\ndata: d.h5\n"
                                     f"noise: {noise}\nmjp: 0.0\n")
    (run / "metrics.json").write_text(json.dumps({
        "test": test, "val": test, "best_epoch": 3, "epochs": 4,
        "initial": {"baseline": "majority class", "test": initial, "val": initial}}))
    return run


def test_table_layout_and_initial_rows(tmp_path):
    a = _fake_run(tmp_path, "a", "classification", "lstm",
                  {"f1": 0.8125, "precision": 0.75, "recall": 0.9, "accuracy": 0.8,
                   "auroc": 0.875, "ap": 0.8},
                  {"f1": 0.0, "precision": 0.0, "recall": 0.0, "accuracy": 0.6})
    b = _fake_run(tmp_path, "b", "classification", "pedestrian_graph",
                  {"f1": 0.5, "precision": 0.5, "recall": 0.5, "accuracy": 0.5},
                  {"f1": 0.0, "precision": 0.0, "recall": 0.0, "accuracy": 0.6})
    c = _fake_run(tmp_path, "c", "classification", "lstm",
                  {"f1": 0.25, "precision": 0.5, "recall": 0.1, "accuracy": 0.4},
                  {"f1": 0.0, "precision": 0.0, "recall": 0.0, "accuracy": 0.6}, noise=5.0)
    text = runs_table([a, b, c])
    lines = text.splitlines()
    assert lines[0] == "### classification (test)"
    header = [h.strip() for h in lines[2].strip("|").split("|")]
    assert header == ["model", "σ (px)", "MJP", "F1", "precision", "recall", "accuracy",
                      "AUROC", "AP", "epochs", "run"]
    rows = [[x.strip() for x in ln.strip("|").split("|")] for ln in lines[4:]]
    # one initial row per data setting (noise 0 and noise 5), before the runs
    assert [r[0] for r in rows] == ["initial: majority class"] * 2 + ["lstm", "pedestrian_graph",
                                                                       "lstm"]
    assert rows[2][3] == "0.812" and rows[2][9] == "3/4" and rows[4][1] == "5"
    # AUROC and AP; a run scored before they existed (b) shows none
    assert rows[2][7:9] == ["0.875", "0.800"] and rows[3][7:9] == ["–", "–"]
    csv_text = runs_table([a], fmt="csv")
    assert csv_text.splitlines()[0].startswith("task,model,σ (px),MJP,F1,precision")
    assert "classification,lstm,0.0,0.0,0.8125,0.75,0.9,0.8,0.875,0.8,3/4,a" in csv_text
    with pytest.raises(ValueError, match=r"format must be one of \['markdown', 'csv'\]"):
        runs_table([a], fmt="html")
