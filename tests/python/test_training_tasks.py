"""The task registry (one object per task), curves.png (units of the tables, best-epoch
marker, whole epochs) and the public task LightningModules, through the example of
docs/training.md run on a small generated file."""
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from bsp_fast.training import tasks as T
from bsp_fast.training.module import TASK_MODULES
from bsp_fast.reporting.curves import curves_figure, plot_curves
from bsp_fast.training.logs import read_logs
from bsp_fast.training.tasks import TABLE_COLUMNS as COLUMNS

pytestmark = [pytest.mark.filterwarnings("ignore::DeprecationWarning"),
              pytest.mark.filterwarnings("ignore::UserWarning")]
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_registry_owns_what_each_task_declares():
    assert list(T.TASKS) == ["classification", "autoencoder", "lifting", "pose_estimation"]
    with pytest.raises(ValueError, match=r"task must be one of \['classification', "
                                         r"'autoencoder', 'lifting', 'pose_estimation'\], "
                                         r"got 'detection'"):
        T.get_task("detection")
    lifting = T.get_task("lifting")
    assert lifting.metric("mpjpe_mm").header == "MPJPE (mm)"
    assert T.get_task("pose_estimation").metric("pck_0.05").header == "PCK@0.05 (%)"
    with pytest.raises(ValueError, match="has no metric 'f1'; allowed: mpjpe_mm"):
        lifting.metric("f1")
    for name, task in T.TASKS.items():
        keys = [m.key for m in task.metrics]
        assert set(task.curves) <= set(keys) and task.baseline == T.BASELINES[name]
        assert [c[2] for c in COLUMNS[name] if c[1] == "m"] == keys  # the tables ask it
        assert TASK_MODULES[name].task == name
    # only where inputs can be deformed do the tables show sigma and MJP
    assert [n for n, t in T.TASKS.items() if t.deformed_inputs] == ["classification",
                                                                    "autoencoder"]
    with pytest.raises(ValueError, match=r"task 'lifting': the batch lacks \['targets_m'\]"):
        lifting.check_batch({"inputs": 0, "visible": 0, "targets": 0, "label": 0, "meta": {}})


def test_reproduce_findings_use_the_task_baselines(tmp_path):
    import yaml

    from bsp_fast import reproduction as R

    doc = yaml.safe_load((REPO / "experiments" / "lifting.yaml").read_text())
    doc["findings"][0]["baseline"] = "constant"  # a classification-only baseline
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    with pytest.raises(ValueError, match=r"baseline 'constant'; allowed for lifting: \[\]"):
        R.load_table(bad)


def test_breakdown_choices_are_task_declarations():
    """bsp-eval --breakdown asks the task object (issue 35): every task declares what is
    kept and binned, and eval_breakdown.py names no task."""
    import ast

    from bsp_fast.training import eval_breakdown as EB

    expected = {"classification": ("logits", "pixel_height", True, True),
                "autoencoder": ("pose_pairs", "pixel_height", False, True),
                "lifting": ("joint_error_mm", "camera_distance", False, True),
                "pose_estimation": ("pose_pairs", "pixel_height", False, False)}
    for name, task in T.TASKS.items():
        got = (task.breakdown_scores, task.breakdown_bins, task.breakdown_per_clip,
               task.breakdown_missing_joints)
        assert got == expected[name], name
        assert task.breakdown_scores in EB.SCORES
        assert task.breakdown_bins in ("pixel_height", "camera_distance")
    assert T.Task.breakdown_scores == ""  # a new task declares its own
    source = Path(EB.__file__).read_text(encoding="utf-8")
    tree = ast.parse(source)
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef))
                  and n.body and isinstance(n.body[0], ast.Expr)}
    strings = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str) and id(n) not in docstrings]
    for name in T.TASKS:  # not as a literal, nor inside any string but the docstrings
        assert f'"{name}"' not in source and f"'{name}'" not in source, name
        assert not [s for s in strings if name in s], name
    assert "spec.name ==" not in source and "task ==" not in source


# ---------------------------------------------------------------------- curves.png
LOGS = {"train/loss": {0: 3.0, 1: 2.0, 2: 1.5}, "val/loss": {0: 2.5, 1: 1.0, 2: 1.2},
        "val/pck_0.05": {0: 0.5, 1: 0.75, 2: 0.7}, "val/pckhn_0.1": {0: 0.25, 1: 0.5, 2: 0.5}}


def _lines(ax) -> dict:
    return {ln.get_label(): ln for ln in ax.get_lines()}


def test_curves_show_percent_best_epoch_and_whole_epochs():
    fig = curves_figure(LOGS, T.get_task("pose_estimation").curve_metrics, initial={"pck_0.05": 0.3, "loss": 4.0})
    loss_ax, metric_ax = fig.axes
    got = _lines(metric_ax)
    # PCK in % as in the tables, not as a fraction
    np.testing.assert_allclose(got["val PCK@0.05 (%)"].get_ydata(), [50.0, 75.0, 70.0])
    np.testing.assert_allclose(got["val PCKhn@0.1 (%)"].get_ydata(), [25.0, 50.0, 50.0])
    assert metric_ax.get_ylabel() == "%"
    dashed = [ln for ln in metric_ax.get_lines() if ln.get_linestyle() == "--"]
    assert [list(ln.get_ydata()) for ln in dashed] == [[30.0, 30.0]]
    # the best epoch (lowest val loss: epoch 2, 1-based) marked on both panels
    for ax in (loss_ax, metric_ax):
        marks = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
        assert len(marks) == 1 and list(marks[0].get_xdata()) == [2, 2]
    assert "best epoch (2)" in [t.get_text() for t in loss_ax.get_legend().get_texts()]
    # whole-number epoch ticks, even for a 3-epoch run
    fig.canvas.draw()
    for ax in (loss_ax, metric_ax):
        ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks), ticks
    # an explicit best epoch (the checkpoint's) wins; mm for lifting
    fig = curves_figure({"val/loss": {0: 1.0, 1: 2.0}, "val/mpjpe_mm": {0: 90.0, 1: 80.0}},
                        T.get_task("lifting").curve_metrics, best_epoch=2)
    assert fig.axes[1].get_ylabel() == "mm"
    np.testing.assert_allclose(_lines(fig.axes[1])["val MPJPE (mm)"].get_ydata(), [90, 80])
    assert [list(ln.get_xdata()) for ln in fig.axes[0].get_lines()
            if ln.get_linestyle() == ":"] == [[2, 2]]


def test_plot_curves_writes_a_png_from_the_csv_logs(tmp_path):
    logs = tmp_path / "logs" / "version_0"
    logs.mkdir(parents=True)
    rows = ["epoch,step,train/loss,val/loss,val/f1"]
    rows += [f"{e},{e * 4 + 3},{3 - e},{2 - e / 2},{0.25 * e}" for e in range(3)]
    (logs / "metrics.csv").write_text("\n".join(rows) + "\n")
    out = plot_curves(read_logs(tmp_path), T.get_task("classification").curve_metrics,
                      tmp_path / "curves.png")
    assert out == tmp_path / "curves.png" and out.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curves.png", "logs"]


# ---------------------------------------------------------------------- docs example
def _doc_example() -> str:
    text = (REPO / "docs" / "training.md").read_text(encoding="utf-8")
    section = text.split("## The task modules in your own Lightning script", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_docs_lightning_example_runs_and_scores_like_bsp_train(tmp_path, monkeypatch,
                                                               capsys):
    from bsp_fast.data.testing import write_clip_file

    code = _doc_example()
    assert len(code.strip().splitlines()) <= 22
    info = write_clip_file(tmp_path / "clips.h5", clips=(24, 8, 8), clip_length=16, seed=2)
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(code, "docs/training.md", "exec"), ns)
    module, trainer, metrics = ns["module"], ns["trainer"], ns["metrics"]
    main = {"mpjpe_mm", "n_mpjpe_mm", "pa_mpjpe_mm", "mpjve_mm"}
    assert set(metrics) == {"loss", "normaliser_fallback"} | main | {k + "_centre" for k in main}
    # predictions: the scored frames only, every test clip; the metric is their error
    frames = len(range(16)[module.scored_frames(16)])
    assert ns["pred"].shape == (info["clips"]["test"], frames, 26, 3)
    err = (ns["pred"] - ns["target"]).double().norm(dim=-1).mean().item() * 1000
    assert metrics["mpjpe_mm"] == pytest.approx(err, rel=1e-5)
    assert f"test MPJPE {metrics['mpjpe_mm']:.1f} mm" in capsys.readouterr().out
    # the model's optimiser settings reached Lightning: AdamW at PoseFormer's 4e-4,
    # decayed by its per-epoch ExponentialLR(0.99) twice
    (config,) = trainer.lr_scheduler_configs
    assert type(config.scheduler).__name__ == "ExponentialLR" and config.interval == "epoch"
    opt = trainer.optimizers[0]
    assert isinstance(opt, torch.optim.AdamW)
    assert opt.param_groups[0]["lr"] == pytest.approx(4e-4 * 0.99 ** 2)
