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
import os
import shutil
from pathlib import Path

from ..atomic import DATASET_FILES, check_outputs, publish, remove, temp_path, write_text

__all__ = ["RunDirectory", "RunError", "default_run_dir", "resolve_checkpoint", "read_run",
           "read_finished",
           "ENV_TMP", "MARKER", "write_marker", "read_marker", "orphaned_runs",
           "resume_hint", "resumable", "continues", "is_temporary", "refuse_unsafe_output",
           "check_run_outputs", "run_inputs", "open_run"]

#: Set by the process that created the temporary run directory, so DDP processes that
#: Lightning starts later (they re-run the command) write into the same directory.
ENV_TMP = "BSP_FAST_RUN_TMP"

#: The file that marks a run directory as incomplete (being written, interrupted or
#: killed): it holds the epoch and step of the last checkpoint; a finished run has none.
MARKER = "incomplete.json"
#: the test split's sums per recording (training/per_recording.py writes it)
PER_RECORDING_FILE = "test_per_recording.json"
#: bsp-eval --breakdown --save's tables (training/eval_breakdown.py)
BREAKDOWN_FILE = "test_breakdown.json"


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
        in_place = self.copy_from is not None and continues(self.copy_from, self.final)
        self.force = force or in_place
        if self.final.exists() and not (force or in_place):
            raise RunError(f"{self.final} exists; pass --force to replace it (or --resume it)",
                           code=3)
        if self.final.exists() and not self.final.is_dir():
            raise RunError(f"{self.final} exists and is not a directory")
        self.tmp = self.final.with_name(tmp_name) if tmp_name else temp_path(self.final)
        self.committed = False
        #: set by the run when it is stopped with a checkpoint worth continuing from: the
        #: directory is then kept as an incomplete run instead of deleted (``left_in``)
        self.keep_incomplete = False
        self.left_in: Path | None = None

    def __enter__(self) -> Path:
        try:
            self.final.parent.mkdir(parents=True, exist_ok=True)
            if self.tmp.exists():  # a stale one of a crashed process with our pid
                shutil.rmtree(self.tmp)
            if self.copy_from is not None:
                shutil.copytree(self.copy_from, self.tmp, symlinks=True)
            else:
                self.tmp.mkdir()
        except OSError as exc:  # read-only or full filesystem, no permission
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise RunError(f"--out {self.final}: cannot write the run directory there "
                           f"({exc.strerror or exc})") from None
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.commit()
        elif self.keep_incomplete:
            self._leave_incomplete()
        else:
            shutil.rmtree(self.tmp, ignore_errors=True)
        return False

    def _leave_incomplete(self) -> None:
        """Publishes the stopped run under its final name (``--resume`` it); where that
        name is taken by something --force may not replace, it stays under ``tmp``."""
        try:
            publish(self.tmp, self.final, force=self.force)
            self.left_in = self.final
        except OSError:
            self.left_in = self.tmp
            return
        self._drop_orphan()

    def _drop_orphan(self) -> None:
        """Killed runs' temporary directories of this ``--out``: the one this run continued
        (what is now published holds all of it and more) and any other (a continuation of
        an incomplete run killed before it saved, or a run the published one replaced):
        a copy left behind would be found again by :func:`orphaned_runs` and continued
        instead of what is published."""
        if self.copy_from is not None and is_temporary(self.copy_from) \
                and self.copy_from != self.tmp:
            remove(self.copy_from)
        for p in orphaned_runs(self.final):  # processes still alive are not listed
            if p != self.tmp:
                remove(p)

    def commit(self) -> None:
        if self.committed:
            return
        try:
            publish(self.tmp, self.final, force=self.force)
        except FileExistsError as exc:  # another run published the same --out meanwhile
            raise RunError(f"{exc}; this run is left in {self.tmp}", code=3) from None
        self.committed = True
        self._drop_orphan()


def is_run_directory(path) -> bool:
    """Whether ``path`` is a folder ``bsp-train`` wrote: ``checkpoints/`` and a
    ``config.yaml`` naming a task and a model (a dataset's config.yaml names neither)."""
    import yaml

    p = Path(path)
    if p.is_symlink() or not (p / "checkpoints").is_dir() or not (p / "config.yaml").is_file():
        return False
    try:
        cfg = yaml.safe_load((p / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(cfg, dict) and "task" in cfg and "model" in cfg


def _dataset_dirs(inputs) -> list:
    """``read_dirs`` of :func:`bsp_fast.atomic.check_outputs` for the inputs that are
    datasets (a folder holding data.csv, or a data.csv): their data.csv, config.yaml and
    media are read."""
    dirs = []
    for item in inputs:
        inp = item[1] if isinstance(item, tuple) else item
        if inp is None:
            continue
        p = Path(inp)
        if p.is_dir() and (p / "data.csv").is_file():
            dirs.append(("the dataset", p, DATASET_FILES))
        elif p.suffix.lower() == ".csv":
            dirs.append(("the dataset", p.parent, DATASET_FILES))
    return dirs


def check_run_outputs(inputs=(), outputs=()) -> None:
    """:func:`bsp_fast.atomic.check_outputs` for the training commands: ``inputs`` (paths
    or ``(name, path)``; "the run's input" by default) and, for a dataset among them, the
    files of its folder. Raises :class:`~bsp_fast.atomic.OutputOverlapError` (exit 2)."""
    named = [i if isinstance(i, tuple) else ("the run's input", i) for i in inputs]
    check_outputs(inputs=named, outputs=outputs, read_dirs=_dataset_dirs(named))


def run_inputs(run, which: str = "best", data=None) -> list:
    """What bsp-eval and bsp-predict read of ``run`` (a run directory or checkpoint),
    found without loading anything: the run, its checkpoint and config.yaml, ``data`` or
    else the data (and HDF5 file) the run's config.yaml names; ``(name, path)`` pairs for
    :func:`check_run_outputs`. A run that cannot be resolved gives what is known (loading
    it says why it cannot be used)."""
    inputs = [("the input run", run), ("the input --data", data)]
    try:
        ckpt, run_dir = resolve_checkpoint(run, which)
    except (RunError, OSError):
        return inputs
    inputs.append(("the input checkpoint", ckpt))
    if run_dir is None:
        return inputs
    inputs.append(("the input run config", Path(run_dir) / "config.yaml"))
    if data is None:
        try:
            resolved = (read_run(run_dir)["config"].get("resolved") or {})
        except Exception:  # unreadable: load_run says so
            resolved = {}
        if isinstance(resolved, dict):
            for key in ("data", "h5"):
                if isinstance(resolved.get(key), str):
                    inputs.append(("the run's input", resolved[key]))
    return inputs


def refuse_unsafe_output(out, *, force: bool, inputs=(), in_place=None) -> None:
    """Checks a run's output folder before any work:

    * it must not be, or hold, one of the run's ``inputs`` (the dataset folder, its
      data.csv, the HDF5 file, a --config file, a checkpoint to start from), through
      symlinks and hard links too, nor replace a file of an input dataset
      (:func:`check_run_outputs`: :class:`~bsp_fast.atomic.OutputOverlapError`, exit 2);
    * an existing ``out`` is replaced only with ``force`` (else ``RunError`` code 3), and
      only when it is an earlier run directory (:func:`is_run_directory`) or ``in_place``
      (the run being resumed): ``--force`` never deletes a folder or file bsp-train did not
      write (``RunError`` code 2).
    """
    out = Path(out)
    check_run_outputs(inputs, [("--out", out)])
    if not (out.exists() or out.is_symlink()):
        return
    if in_place is not None and continues(in_place, out):
        return
    if not force:
        raise RunError(f"{out} exists; pass --force to replace it (or --resume it)", code=3)
    if not is_run_directory(out):
        what = "a folder" if out.is_dir() else "a file"
        raise RunError(f"--out {out} is {what} that bsp-train did not write (no "
                       "checkpoints/ and run config.yaml); --force replaces only an earlier "
                       "run directory", code=2)


def write_marker(run_dir, **fields) -> None:
    """Writes (replaces) ``incomplete.json`` of a run being written or left incomplete."""
    doc = dict(fields, updated=_dt.datetime.now().isoformat(timespec="seconds"))
    write_text(Path(run_dir) / MARKER, json.dumps(doc, indent=2) + "\n")


def read_marker(run_dir) -> dict | None:
    """``incomplete.json`` of a run directory (None: a finished run or not a run)."""
    p = Path(run_dir) / MARKER
    if not p.is_file():
        return None
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def _alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, ValueError, TypeError):
        return False
    except PermissionError:
        return True
    return True


def is_temporary(path) -> bool:
    """Whether ``path`` is a run's temporary directory (``.NAME.tmp-...``, see
    :func:`bsp_fast.atomic.temp_path`), e.g. one a killed run left."""
    name = Path(path).name
    return name.startswith(".") and ".tmp-" in name


def orphaned_runs(out) -> list:
    """Temporary directories of runs of ``--out out`` whose process died (``kill -9``, a
    power cut) after saving a checkpoint, newest checkpoint first: ``--resume out``
    continues the first."""
    out = Path(out).absolute()
    found = []
    for p in out.parent.glob(f".{out.name}.tmp-*"):
        marker = read_marker(p)
        last = p / "checkpoints" / "last.ckpt"
        if marker is None or not last.is_file() or not (p / "config.yaml").is_file():
            continue
        if marker.get("pid") is not None and _alive(marker["pid"]) \
                and marker.get("state") == "running":
            continue  # still training
        found.append((last.stat().st_mtime, p))
    return [p for _, p in sorted(found, reverse=True)]


def continues(source, out) -> bool:
    """Whether a run resumed from ``source`` continues ``out`` itself (and may replace it
    without --force): ``source`` is ``out``, or a killed continuation of the incomplete
    run ``out`` (its temporary directory ``.OUT.tmp-*`` beside it)."""
    source, out = Path(source), Path(out)
    if Path(os.path.realpath(source)) == Path(os.path.realpath(out)):
        return True
    return (is_temporary(source) and source.name.startswith(f".{out.name}.tmp-")
            and Path(os.path.realpath(source.parent)) == Path(os.path.realpath(out.parent))
            and read_marker(out) is not None)


def _step(run_dir) -> int:
    step = (read_marker(run_dir) or {}).get("step")
    return step if isinstance(step, int) else -1


def resumable(run_dir) -> Path | None:
    """The incomplete run to continue for ``run_dir``: the directory itself if it is an
    interrupted run, or a killed continuation of it that saved a later step (its
    temporary directory); where ``run_dir`` does not exist, a killed run's temporary
    directory (None: nothing to continue)."""
    p = Path(run_dir)
    if p.is_dir():
        if read_marker(p) is None or not (p / "checkpoints" / "last.ckpt").is_file():
            return None  # a finished run, or not a run
        # stopped, continued, then killed after a save: the continuation is further on
        # (a continuation killed before its first save holds a copy: step None)
        ahead = [o for o in orphaned_runs(p) if _step(o) > _step(p)]
        return max(ahead, key=_step) if ahead else p
    orphans = orphaned_runs(p)
    return orphans[0] if orphans else None


def resume_hint(run_dir) -> str:
    """``interrupted at epoch E step S; continue with: bsp-train --resume DIR``."""
    m = read_marker(run_dir) or {}
    where = f"epoch {m.get('epoch', '?')} step {m.get('step', '?')}"
    return f"{where}; continue with: bsp-train --resume {run_dir}"


def resolve_checkpoint(path, which: str = "best") -> tuple:
    """``path`` is a run directory or a ``.ckpt`` file -> ``(ckpt_path, run_dir or None)``.
    ``which``: ``best`` or ``last`` checkpoint of a run directory."""
    p = Path(path)
    if which == "last" and not p.is_file():
        # a run killed before it could be published, or an incomplete run's continuation
        # killed after saving a later step (a finished run: itself)
        p = resumable(p) or p
    if p.is_dir():
        marker = read_marker(p)
        if marker is not None and which != "last":
            raise RunError(f"{p}: an incomplete run ({marker.get('state', 'stopped')} at "
                           f"{resume_hint(p)}); it has no final metrics yet")
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


def read_finished(runs, split: str = "test") -> list:
    """``[(run directory, config, metrics)]`` of finished runs that scored ``split``: what
    ``bsp-eval --table`` and bsp-train's closing table render
    (:func:`bsp_fast.reporting.run_tables.runs_table`). RunError naming the run that has
    no metrics, or none of ``split``, and how to add them."""
    loaded = []
    for path in runs:
        run = read_run(path)
        if not run["metrics"]:
            raise RunError(f"{path}: no metrics.json (an unfinished or failed run?)")
        if run["metrics"].get(split) is None:
            raise RunError(f"{path}: metrics.json has no {split!r} metrics "
                           f"(bsp-eval {path} --split {split} --save adds them)")
        loaded.append((Path(path), run["config"], run["metrics"]))
    return loaded


def write_json(obj, path) -> None:
    """JSON with NaN/inf written as null (strict JSON readers choke on NaN)."""
    write_text(path, json.dumps(_finite(obj), indent=2) + "\n")


def _finite(obj):
    import math

    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


# ---------------------------------------------------------------------- opening a run
def open_run(run, which: str = "best", what: str = "") -> dict:
    """The one place a run is opened (``bsp-train --resume``, ``bsp-eval``, ``bsp-predict``
    and so ``bsp-reproduce``'s noisy-box scores): the ``which`` checkpoint (best or last)
    of a run directory or a ``.ckpt``, its folder (None for a bare checkpoint), the
    checkpoint's saved hyper-parameters (``info``) and the run's config (its
    ``config.yaml``, else the checkpoint's), checked to be one task and model. Returns
    ``{"ckpt", "run_dir", "info", "config"}``; a :class:`RunError` (prefixed ``what``)
    names a broken checkpoint or the mismatch, before any work."""
    if which not in ("best", "last"):
        raise ValueError(f"which must be one of ['best', 'last'], got {which!r}")
    ckpt, run_dir = resolve_checkpoint(run, which)
    try:  # truncated, foreign or pickled files: one line
        from .checkpoint_file import checkpoint_info

        info = checkpoint_info(ckpt)
    except ValueError as exc:
        raise RunError(f"{what}{exc}") from None
    config = read_run(run_dir)["config"] if run_dir is not None else \
        (info.get("config") or {})
    if "task" in config and \
            (info.get("task"), info.get("model")) != (config.get("task"), config.get("model")):
        where = run_dir / "config.yaml" if run_dir is not None else "its saved config"
        raise RunError(f"{what}{ckpt} is a {info.get('task')!r} checkpoint of model "
                       f"{info.get('model')!r}, but its run is {config.get('task')!r}: "
                       f"{where} is a {config.get('task')!r} run of model "
                       f"{config.get('model')!r}; refusing to use it as either")
    return {"ckpt": Path(ckpt), "run_dir": run_dir, "info": info, "config": config}
