"""Optional dependencies: a missing one is an ImportError that names the extra to install."""
from __future__ import annotations

import importlib

__all__ = ["require"]

EXTRAS = {"torch": "torch", "lightning": "torch", "torchmetrics": "torch",
          "cv2": "preview", "matplotlib": "preview", "dask": "distributed",
          "distributed": "distributed"}


def require(module: str, needed_by: str = "bsp_fast.data"):
    """Imports ``module``; if it is missing, raises ImportError saying which extra of
    bsp_fast provides it (``pip install 'bsp_fast[torch]'``)."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        extra = EXTRAS.get(module.split(".")[0], "torch")
        raise ImportError(
            f"{needed_by} needs {module.split('.')[0]}, which is not installed ({exc}). "
            f"Install the '{extra}' extra: pip install 'bsp_fast[{extra}]' "
            f"(from a source tree: pip install '.[{extra}]')") from exc
