"""A command or option whose optional extra is not installed says which extra to install
(``pip install 'bsp_fast[...]'``), in one line and without a traceback: bsp-preview,
--scheduler dask, bsp-train, --logger."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PYTHON = str(ROOT / "python")


def _env(**extra) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([PYTHON] + sys.path), **extra)


def _without(modules, code: str, cwd=ROOT) -> subprocess.CompletedProcess:
    """Runs python ``code`` with ``modules`` unimportable (as if their extra were not
    installed)."""
    hide = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    return subprocess.run([sys.executable, "-c", hide + code], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=300)


def test_bsp_preview_without_the_preview_extra_names_it(tmp_path):
    (tmp_path / "c.h5").write_bytes(b"")  # an input that exists: the extra is said first
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


def test_bsp_train_without_jsonargparse_names_the_torch_extra():
    r = _without(["jsonargparse"], "from bsp_fast.__main__ import main\n"
                 "sys.exit(main(['train', '--help']))")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("bsp-train: bsp-train needs jsonargparse, which is not "
                               "installed. Install the 'torch' extra: pip install "
                               "'bsp_fast[torch]'"), r.stderr


def test_logger_without_the_loggers_extra_names_it(tmp_path):
    from bsp_fast._extras import install_hint, require_any

    with pytest.raises(ImportError, match=r"pip install 'bsp_fast\[loggers\]'"):
        require_any(["no_such_module_bsp"], "x", extra="loggers")
    with pytest.raises(ValueError, match="no extra provides 'numpyz'"):
        install_hint("numpyz", "x")
    # both loggers in one process without the extra (one import of Lightning, not two)
    code = ("import bsp_fast.training.setup as t, bsp_fast.training.config as C\n"
            "for kind in ('wandb', 'tensorboard'):\n"
            "    cfg = C.defaults() | {'logger': kind, 'out': 'r', 'accelerator': 'cpu'}\n"
            "    try:\n        t.make_trainer(cfg, __import__('pathlib').Path('r'), '32')\n"
            "    except C.ConfigError as e:\n        print('ConfigError:', e)\n")
    r = _without(["wandb", "tensorboard", "tensorboardX"], code, cwd=tmp_path)
    for kind in ("wandb", "tensorboard"):
        assert (f"ConfigError: --logger {kind} needs {kind}, which is not installed. "
                "Install the 'loggers' extra: pip install 'bsp_fast[loggers]'") in r.stdout, \
            r.stdout + r.stderr[-2000:]
    assert "loggers = [" in (ROOT / "pyproject.toml").read_text()
