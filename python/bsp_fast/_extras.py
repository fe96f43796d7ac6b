"""Optional dependencies: a missing one is an ImportError that names the extra to install.

Every extra of ``pyproject.toml`` is here: torch (torch, lightning, torchmetrics,
matplotlib for bsp-train's curves.png, jsonargparse for its command line, scipy for
bsp-reproduce's bootstrap intervals), preview (cv2,
matplotlib), distributed (dask, distributed) and loggers (tensorboard, wandb for
``bsp-train --logger``).
"""
from __future__ import annotations

import importlib
import importlib.util

__all__ = ["require", "require_any", "install_hint", "EXTRAS"]

#: The extra that provides each optional top-level module (its default one).
EXTRAS = {"torch": "torch", "lightning": "torch", "torchmetrics": "torch",
          "jsonargparse": "torch", "scipy": "torch", "cv2": "preview", "matplotlib": "preview",
          "dask": "distributed", "distributed": "distributed", "tensorboard": "loggers",
          "tensorboardX": "loggers", "wandb": "loggers"}
#: pip's name of a module whose import name differs.
PIP_NAMES = {"cv2": "opencv-python-headless"}


def install_hint(module: str, needed_by: str, extra: str | None = None) -> str:
    """``"<needed_by> needs <module>, which is not installed. Install the '<extra>' extra:
    pip install 'bsp_fast[<extra>]' ..."``."""
    top = module.split(".")[0]
    if extra is None and top not in EXTRAS:
        raise ValueError(f"no extra provides {top!r}; known modules: {', '.join(EXTRAS)}")
    extra = extra or EXTRAS[top]
    name = PIP_NAMES.get(top, top)
    shown = top if name == top else f"{top} ({name})"
    return (f"{needed_by} needs {shown}, which is not installed. Install the '{extra}' "
            f"extra: pip install 'bsp_fast[{extra}]' (from a source tree: "
            f"pip install '.[{extra}]')")


def require(module: str, needed_by: str = "bsp_fast.data", extra: str | None = None):
    """Imports ``module``; if it is missing, raises ImportError saying which extra of
    bsp_fast provides it (``pip install 'bsp_fast[torch]'``); ``extra`` overrides the
    default extra of the module."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{install_hint(module, needed_by, extra)} ({exc})") from exc


def require_any(modules, needed_by: str, extra: str | None = None) -> str:
    """The first of ``modules`` that is installed (found, not imported); ImportError
    naming the extra when none is."""
    modules = list(modules)
    for m in modules:
        if importlib.util.find_spec(m) is not None:
            return m
    raise ImportError(install_hint(modules[0], needed_by, extra))
