"""Issue 28, the rough edges a new user meets: one test (at least) per item."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
PYTHON = str(ROOT / "python")


def _console_scripts() -> dict:
    """[project.scripts] of pyproject.toml: {name: "module:function"}."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.scripts]\n", 1)[1].split("\n[", 1)[0]
    return dict(re.findall(r'^(bsp-[\w-]+) = "([\w.:]+)"', block, re.M))


def _env(**extra) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([PYTHON] + sys.path), **extra)


# ------------------------------------------------------------------ 13: torchmetrics style
def test_single_metric_classes_and_collection_match_hand_counts():
    import torch
    from torchmetrics import Metric, MetricCollection

    from bsp_fast.metrics import (BinaryAccuracy, BinaryF1Score, BinaryPrecision,
                                  BinaryRecall, ClassificationMetrics,
                                  classification_collection)

    # batch 1 (labels): tp 2, fp 1, fn 1, tn 1; batch 2 (logits, threshold 0 -> 1, 0, 1
    # against 1, 1, 0): tp 1, fn 1, fp 1. In all: tp 3, fp 2, fn 2, tn 1 (by hand).
    batches = [(torch.tensor([1, 1, 0, 0, 1]), torch.tensor([1, 0, 0, 1, 1])),
               (torch.tensor([0.9, -2.0, 3.0]), torch.tensor([1, 1, 0]))]
    want_first = {"precision": 2 / 3, "recall": 2 / 3}
    singles = {"f1": BinaryF1Score(), "precision": BinaryPrecision(),
               "recall": BinaryRecall(), "accuracy": BinaryAccuracy()}
    coll = classification_collection(prefix="val/")
    both = ClassificationMetrics()
    assert isinstance(coll, MetricCollection)
    for m in singles.values():
        assert isinstance(m, Metric)
    for k, (p, t) in enumerate(batches):
        for m in list(singles.values()) + [coll, both]:
            m.update(p, t)
        if k == 0:
            assert float(singles["precision"].compute()) == pytest.approx(want_first["precision"])
            assert float(singles["recall"].compute()) == pytest.approx(want_first["recall"])
    want = {"f1": 6 / (6 + 2 + 2), "precision": 3 / 5, "recall": 3 / 5, "accuracy": 4 / 8}
    for name, m in singles.items():
        value = m.compute()
        assert value.ndim == 0 and value.dtype == torch.float64
        assert float(value) == pytest.approx(want[name]), name
    got = coll.compute()
    assert sorted(got) == ["val/accuracy", "val/f1", "val/precision", "val/recall"]
    for name in want:
        assert float(got[f"val/{name}"]) == pytest.approx(want[name])
        assert float(both.compute()[name]) == pytest.approx(want[name])
    # one set of confusion counts for the four (torchmetrics' compute groups)
    assert len(coll.compute_groups) == 1
    assert singles["f1"].confusion_matrix().tolist() == [[1, 2], [2, 3]]


# ------------------------------------------------------------------ 15: make demo
@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_demo_prints_the_commands_a_user_types():
    scripts = _console_scripts()
    # -o install: do not install; PY=true: run nothing, only the echoed commands print
    r = subprocess.run(["make", "--no-print-directory", "-o", "install", "demo", "PY=true"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 5, r.stdout
    for line in lines:
        assert line.startswith("$ "), line
        assert "$(" not in line and "-m bsp_fast" not in line and "build/.python" not in line
        prog = line.split()[1]
        assert prog in scripts or line.startswith("$ python tools/"), line
    assert lines[0] == "$ bsp-synth demo-out/dataset --preset sample --force"
    assert lines[-1] == "$ bsp-eval --table demo-out/runs/lifting-lstm"


# ------------------------------------------------------------------ 2: optional extras
def _without(modules, code: str, cwd=ROOT) -> subprocess.CompletedProcess:
    """Runs python ``code`` with ``modules`` unimportable (as if their extra were not
    installed)."""
    hide = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    return subprocess.run([sys.executable, "-c", hide + code], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=300)


def test_bsp_preview_without_the_preview_extra_names_it(tmp_path):
    r = _without(["cv2"], "from bsp_fast.__main__ import main\n"
                 f"sys.exit(main(['preview', 'clips', {str(tmp_path / 'c.h5')!r}, "
                 f"'--out', {str(tmp_path / 'x.png')!r}]))")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert r.stderr.startswith("bsp-preview: bsp-preview needs cv2 (opencv-python-headless), "
                               "which is not installed. Install the 'preview' extra: "
                               "pip install 'bsp_fast[preview]'"), r.stderr
    # the API raises the same ImportError; matplotlib (3D views) names the same extra
    r = _without(["matplotlib"], "from bsp_fast.preview.plot3d import SkeletonFigure\n"
                 "import numpy as np\n"
                 "try:\n    SkeletonFigure([('a', (0, 0))], -np.ones(3), np.ones(3))\n"
                 "except ImportError as e:\n    print(e)\n")
    assert "needs matplotlib" in r.stdout and "pip install 'bsp_fast[preview]'" in r.stdout, \
        r.stdout + r.stderr


def test_scheduler_dask_without_the_distributed_extra_names_it(tmp_path):
    r = _without(["distributed", "dask"], "from bsp_fast.__main__ import main\n"
                 f"sys.exit(main(['synth', {str(tmp_path / 'ds')!r}, '--clips', '1', "
                 "'--scheduler', 'dask', '--quiet']))")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "pip install 'bsp_fast[distributed]'" in r.stderr
    assert not (tmp_path / "ds").exists()


def test_logger_without_the_loggers_extra_names_it(tmp_path):
    from bsp_fast._extras import install_hint, require_any

    with pytest.raises(ImportError, match=r"pip install 'bsp_fast\[loggers\]'"):
        require_any(["no_such_module_bsp"], "x", extra="loggers")
    with pytest.raises(ValueError, match="no extra provides 'numpyz'"):
        install_hint("numpyz", "x")
    for kind in ("wandb", "tensorboard"):
        code = (f"import bsp_fast.training.train as t, bsp_fast.training.config as C\n"
                f"cfg = C.defaults() | {{'logger': {kind!r}, 'out': 'r', "
                "'accelerator': 'cpu'}\n"
                "try:\n    t.make_trainer(cfg, __import__('pathlib').Path('r'), '32')\n"
                "except C.ConfigError as e:\n    print('ConfigError:', e)\n")
        r = _without(["wandb", "tensorboard", "tensorboardX"], code, cwd=tmp_path)
        assert (f"ConfigError: --logger {kind} needs {kind}, which is not installed. "
                "Install the 'loggers' extra: pip install 'bsp_fast[loggers]'") in r.stdout, \
            r.stdout + r.stderr[-2000:]
    assert "loggers = [" in (ROOT / "pyproject.toml").read_text()
