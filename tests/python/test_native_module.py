"""Where the C++ module comes from (bsp_fast/_native.py): this package's folder, else a
folder bsp_fast/ on sys.path (a development build tree, an installed copy); every Python
module from this package's own folder only."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import bsp_fast
from bsp_fast import _native

PYTHON = Path(__file__).resolve().parents[2] / "python"


def test_core_is_loaded_once_under_its_package_name():
    import bsp_fast._core as imported

    assert _native.core is bsp_fast._core is imported is sys.modules["bsp_fast._core"]
    assert _native.load() is _native.core
    assert isinstance(bsp_fast.Error, type) and bsp_fast.Error.__module__ == "bsp_fast._core"


def test_another_bsp_fast_folder_on_the_path_lends_the_core_only(tmp_path):
    """A Python module found only in another bsp_fast/ folder on the path (an older install
    of a module since deleted) is not imported; the C++ module there is."""
    other = tmp_path / "other" / "bsp_fast"
    other.mkdir(parents=True)
    (other / "only_there.py").write_text("X = 1\n")
    code = ("import importlib, bsp_fast\n"
            "try:\n    importlib.import_module('bsp_fast.only_there')\n"
            "except ModuleNotFoundError:\n    print('not found')\n"
            "print(bsp_fast.__path__ == [bsp_fast.__path__[0]])\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PYTHON), str(tmp_path / "other")]))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["not", "found", "True"]


def test_the_core_imports_by_name_in_a_fresh_process(tmp_path):
    """``import bsp_fast._core`` (what unpickling a core object in a worker process does)
    finds the module _native loaded, wherever the core lies on the path."""
    code = ("import sys, bsp_fast._core as c\n"
            "print(c is sys.modules['bsp_fast._core'] and hasattr(c, 'plan_clips'))\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(PYTHON), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 0 and r.stdout.split() == ["True"], r.stderr[-2000:]
