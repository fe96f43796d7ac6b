"""The one place that loads the private C++ module, ``bsp_fast._core``, and hands it on as
``core``.

The module is looked for in this package's folder (an installed package), then in a
folder ``bsp_fast/`` of each ``sys.path`` entry, in order: a development build tree
(``PYTHONPATH=python:build/dev/py``, its ``build/dev/py/bsp_fast/_core*.so``), or the
installed package's copy when the source tree's ``python/`` comes first on the path. Only
the C++ module is looked up that way: every Python module comes from this package's own
folder, so a module deleted from the source tree is not found in an older install.

The module is registered as ``bsp_fast._core`` in ``sys.modules``; the package root loads
it first, so ``import bsp_fast._core`` by name (unpickling a core object in a worker
process) finds it.
"""
from __future__ import annotations

import os
import sys
from importlib import machinery, util

NAME = f"{__package__}._core"


def _search_path() -> list:
    here = os.path.dirname(os.path.abspath(__file__))
    package = os.path.basename(here)
    return [here] + [os.path.join(entry or os.curdir, package) for entry in sys.path]


def load():
    """The C++ module, loaded once (later calls return the same module)."""
    if NAME in sys.modules:
        return sys.modules[NAME]
    spec = machinery.PathFinder.find_spec(NAME, _search_path())
    if spec is None:  # pragma: no cover - only hit on a broken install
        raise ImportError(
            f"bsp_fast's C++ core ({NAME}) is not built: no _core module in this package's "
            "folder or a bsp_fast/ folder on sys.path. Install with `pip install .` (or "
            "`make test`) from the source tree.", name=NAME)
    try:
        module = util.module_from_spec(spec)
        sys.modules[NAME] = module
        spec.loader.exec_module(module)
    except ImportError as exc:  # pragma: no cover - a broken build or a missing library
        sys.modules.pop(NAME, None)
        raise ImportError(f"bsp_fast's C++ core ({spec.origin}) cannot be loaded: {exc}. "
                          "Install with `pip install .` (or `make test`) from the source "
                          "tree.", name=NAME) from exc
    return module


core = load()
