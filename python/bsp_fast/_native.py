"""The one place that imports the private C++ module."""
from __future__ import annotations

# (bsp_fast/__init__.py extends the package path, so a development build tree on
# PYTHONPATH=python:build/dev/py provides `_core` too.)
try:
    from . import _core  # type: ignore[attr-defined]
except ImportError as exc:  # pragma: no cover - only hit on a broken install
    raise ImportError(
        "bsp_fast's C++ core (bsp_fast._core) is not built or cannot be loaded: "
        f"{exc}. Install with `pip install .` (or `make test`) from the source tree."
    ) from exc

core = _core
