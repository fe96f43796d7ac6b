"""The one place that imports the private C++ module."""
from __future__ import annotations

# During development the module may live in a build tree (PYTHONPATH=python:build/dev/py);
# extend the package path so `bsp_fast._core` is found there too.
import pkgutil as _pkgutil


try:
    from . import _core  # type: ignore[attr-defined]
except ImportError as exc:  # pragma: no cover - only hit on a broken install
    raise ImportError(
        "bsp_fast's C++ core (bsp_fast._core) is not built or cannot be loaded: "
        f"{exc}. Install with `pip install .` (or `make test`) from the source tree."
    ) from exc

core = _core
del _pkgutil
