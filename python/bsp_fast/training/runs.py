"""Run directories: written under a temporary name, renamed when complete.

A finished run directory holds::

    config.yaml              the resolved options (usable as --config)
    metrics.json             test metrics, best-epoch val metrics, initial metrics
    test_per_recording.json  the sums behind each test metric, per test recording
    curves.png               loss and main metrics per epoch
    checkpoints/best.ckpt    lowest val loss;  checkpoints/last.ckpt  end of the last epoch
    logs/version_N/metrics.csv   CSV logs (one version per start: resumes add one)
"""
from __future__ import annotations

import datetime as _dt
import json
import shutil
from pathlib import Path

from ..atomic import publish, temp_path

__all__ = ["RunDirectory", "RunError", "default_run_dir", "resolve_checkpoint", "read_run",
           "ENV_TMP"]

#: Set by the process that created the temporary run directory, so DDP processes that
#: Lightning starts later (they re-run the command) write into the same directory.
ENV_TMP = "BSP_FAST_RUN_TMP"


class RunError(Exception):
    """A run directory or checkpoint that cannot be used (exit code 1, or 3 for exists)."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


def default_run_dir(task: str, model: str, root="runs") -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(root) / f"{task}-{model}-{stamp}"


class RunDirectory:
    """``with RunDirectory(final, force=..., copy_from=...) as tmp:`` writes into ``tmp``;
    on success ``tmp`` replaces ``final`` (the old one is removed only after the new one
    is in place); on an exception ``tmp`` is deleted and ``final`` is untouched.

    ``copy_from`` (a resumed run) seeds ``tmp`` with that directory's files. Replacing an
    existing ``final`` needs ``force`` or ``final == copy_from``. ``tmp_name``: the
    temporary directory's name (default ``.NAME.tmp-PID-RANDOM``; multi-machine DDP runs use one
    every rank can compute).
    """

    def __init__(self, final, *, force: bool = False, copy_from=None, tmp_name=None):
        self.final = Path(final).absolute()
        self.copy_from = None if copy_from is None else Path(copy_from).absolute()
        in_place = self.copy_from is not None and self.copy_from == self.final
        self.force = force or in_place
        if self.final.exists() and not (force or in_place):
            raise RunError(f"{self.final} exists; pass --force to replace it (or --resume it)",
                           code=3)
        if self.final.exists() and not self.final.is_dir():
            raise RunError(f"{self.final} exists and is not a directory")
        self.tmp = self.final.with_name(tmp_name) if tmp_name else temp_path(self.final)
        self.committed = False

    def __enter__(self) -> Path:
        self.final.parent.mkdir(parents=True, exist_ok=True)
        if self.tmp.exists():  # a stale one of a crashed process with our pid
            shutil.rmtree(self.tmp)
        if self.copy_from is not None:
            shutil.copytree(self.copy_from, self.tmp, symlinks=True)
        else:
            self.tmp.mkdir()
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.commit()
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)
        return False

    def commit(self) -> None:
        if self.committed:
            return
        publish(self.tmp, self.final, force=self.force)
        self.committed = True


def resolve_checkpoint(path, which: str = "best") -> tuple:
    """``path`` is a run directory or a ``.ckpt`` file -> ``(ckpt_path, run_dir or None)``.
    ``which``: ``best`` or ``last`` checkpoint of a run directory."""
    p = Path(path)
    if p.is_dir():
        ckpt = p / "checkpoints" / f"{which}.ckpt"
        if not ckpt.is_file():
            raise RunError(f"{p}: not a bsp-train run directory (no checkpoints/{which}.ckpt)")
        return ckpt, p
    if p.is_file():
        if p.suffix != ".ckpt":
            raise RunError(f"{p}: expected a run directory or a .ckpt checkpoint")
        run = p.parent.parent if p.parent.name == "checkpoints" else None
        if run is not None and not (run / "config.yaml").is_file():
            run = None
        return p, run
    raise RunError(f"{p}: no such run directory or checkpoint")


def read_run(run_dir) -> dict:
    """``{"config": dict, "metrics": dict or None}`` of a run directory."""
    import yaml

    run = Path(run_dir)
    cfg_path = run / "config.yaml"
    if not cfg_path.is_file():
        raise RunError(f"{run}: not a bsp-train run directory (no config.yaml)")
    cfg = yaml.safe_load(cfg_path.read_text(encoding="utf-8")) or {}
    metrics_path = run / "metrics.json"
    metrics = (json.loads(metrics_path.read_text(encoding="utf-8"))
               if metrics_path.is_file() else None)
    return {"config": cfg, "metrics": metrics}


def write_json(obj, path) -> None:
    """JSON with NaN/inf written as null (strict JSON readers choke on NaN)."""
    Path(path).write_text(json.dumps(_finite(obj), indent=2) + "\n", encoding="utf-8")


def _finite(obj):
    import math

    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj
