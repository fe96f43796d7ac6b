"""``bsp-eval RUN_OR_CKPT``: re-evaluate a checkpoint; ``bsp-eval --table RUN...``: runs
side by side in the layout of the report's tables.

Python: ``bsp_fast.evaluate("runs/lifting-martinez", split="test")`` -> :class:`EvalResult`;
``breakdown("runs/lifting-martinez")`` -> the test split's breakdown document
(``bsp-eval RUN --breakdown``, :mod:`bsp_fast.training.eval_breakdown`).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from ..command_line import ArgumentParser, HelpFormatter, run_command
from . import config as C
from .overrides import add_overrides, given_overrides
from .runs import RunError, check_run_outputs, open_run, resolve_checkpoint, run_inputs, \
    write_json

__all__ = ["evaluate", "breakdown", "main", "EvalResult", "load_run", "run_config",
           "prepare_scoring"]

SPLIT_STAGES = {"test": "test", "val": "validate"}


@dataclass
class EvalResult:
    """``metrics``: the split's metrics (mm for 3D) under the run's data settings unless
    overridden; ``config``: the settings used; ``per_recording``: the test split's sums
    per recording (a ``test`` section of ``test_per_recording.json``; None for val)."""
    task: str
    model: str
    split: str
    metrics: dict
    checkpoint: Path
    config: dict
    clips: int = 0
    recordings: int = 0
    per_recording: dict | None = None


def load_run(run, which: str = "best", data=None, **overrides):
    """``(saved, cfg, ckpt, h5)`` of a run directory or checkpoint: the rebuilt net
    (:class:`~bsp_fast.training.scorer.SavedModel`) and :func:`run_config`'s answer."""
    cfg, ckpt, h5 = run_config(run, which, data, **overrides)
    from .scorer import load_saved  # torch: once the run is known to exist

    try:
        saved = load_saved(ckpt)
    except ValueError as exc:
        raise RunError(str(exc)) from None
    return saved, cfg, ckpt, h5


def run_config(run, which: str = "best", data=None, **overrides) -> tuple:
    """``(cfg, ckpt, h5)`` of a run directory or checkpoint: its saved config with
    ``overrides`` (bsp-train option names) applied and the precision it trained in, and
    the data to read (``data``, else the run's dataset folder if it still exists, so its
    conversion is compared with its data.csv, else the HDF5 file the run used if it still
    exists, else its ``data``)."""
    opened = open_run(run, which)
    ckpt, run_dir, info = opened["ckpt"], opened["run_dir"], opened["info"]
    cfg = C.defaults()
    saved = {k: v for k, v in (info.get("config") or {}).items() if k in C.BY_NAME}
    cfg.update(C.normalise(saved, f"{ckpt} (saved config)"))
    given = C.normalise({k: v for k, v in overrides.items() if v is not None})
    if "mix_data" in given:  # more files (e.g. a dataset to test on): the mix's stay
        given["mix_data"] = {**cfg["mix_data"], **given["mix_data"]}
    cfg.update(given)
    h5 = None
    # the run's config.yaml, as open_run read it (a bare checkpoint has no "resolved")
    resolved = (opened["config"].get("resolved") or {}) if run_dir is not None else {}
    if overrides.get("precision") is None and resolved.get("precision") in C.PRECISIONS:
        cfg["precision"] = resolved["precision"]  # what the run trained in, not re-decided
    if data is not None:
        cfg["data"] = str(data)
    elif run_dir is not None:
        used, folder = resolved.get("h5"), resolved.get("data")
        if isinstance(folder, str) and (Path(folder).is_dir() or (
                Path(folder).name == "data.csv" and Path(folder).is_file())):
            # the run's dataset (absolute path): its conversion (the run's file in the
            # cache) is checked against its data.csv, converted again when out of date
            cfg["data"] = folder
        elif used and Path(used).is_file():
            h5 = used
    if cfg.get("data") is None and h5 is None:
        raise RunError(f"{ckpt}: the checkpoint names no data; pass --data")
    return cfg, ckpt, h5


def prepare_scoring(cfg: dict, saved) -> str:
    """Sets the run's ``threads`` (``torch.set_num_threads``, when given) and returns the
    Trainer precision ``bsp-eval`` scores it in and ``bsp-predict`` predicts in (so the
    predictions are the outputs that were scored): the run's ``precision`` (``auto``
    resolved for its model and ``cfg["accelerator"]``), float32 where bf16 is not native
    (e.g. a bf16 GPU run on a CPU without bf16 instructions)."""
    from .precision import native_bf16, resolve_precision

    if cfg["threads"]:
        import torch

        torch.set_num_threads(cfg["threads"])
    precision = resolve_precision(cfg["precision"], cfg["accelerator"], saved.net)
    if precision.startswith("bf16") and not native_bf16(cfg["accelerator"]):
        precision = "32"
    return precision


def evaluate(run, split: str = "test", data=None, *, which: str = "best",
             batch_size: int | None = None, workers: int | None = None,
             accelerator: str | None = None, noise: float | None = None, mjp=None,
             limit_batches: int | None = None, quiet: bool = True,
             box_noise=None, observers=(), **overrides) -> EvalResult:
    """Scores the ``which`` checkpoint (best or last) of run directory or checkpoint
    ``run`` on ``split`` (test or val) with the run's data settings (the evaluation noise
    is fixed per clip), any of them overridable; reproduces the run's ``metrics.json``
    (the same steps and precision as its ``Trainer.test``, in plain PyTorch:
    :mod:`.scorer`). Every clip of the split is scored whatever ``batch_size`` (the run's
    ``limit_batches`` is not carried over; ``limit_batches`` here limits on purpose), and
    the result counts the clips and recordings scored. ``box_noise=(scale, shift)``
    (pose_estimation) scores the crops of noisy boxes instead: side x U[1 - scale,
    1 + scale], centre moved by U[-shift, shift] x side per axis, fixed per clip by the
    evaluation seed (docs/data.md, "Box noise"). ``observers``: objects whose
    ``update(spec, net, output, batch)`` sees every scored batch and whose
    ``start(spec, net)``, where they have one, runs before the first."""
    if split not in SPLIT_STAGES:
        raise ValueError(f"split must be one of {list(SPLIT_STAGES)}, got {split!r}")
    saved, cfg, ckpt, h5 = load_run(run, which, data, batch_size=batch_size, workers=workers,
                                    accelerator=accelerator, noise=noise, mjp=mjp,
                                    quiet=quiet, **overrides)
    from .scorer import device_of, score
    from .setup import make_datamodule, prepare_data

    precision = prepare_scoring(cfg, saved)
    dm = make_datamodule(cfg, h5, plain=cfg.get("mix") is None)
    if box_noise is not None:
        if saved.task != "pose_estimation":
            raise ValueError(f"box noise perturbs pose-estimation crop boxes; this is a "
                             f"{saved.task} run")
        dm.dataset_options["box_noise"] = tuple(float(x) for x in box_noise)
    prepare_data(dm, stages=(SPLIT_STAGES[split],))
    for observer in observers:  # e.g. the breakdown reads what batches lack from the file
        observer.h5_path = str(dm.datasets[split].h5_path)
    loader = dm.test_dataloader() if split == "test" else dm.val_dataloader()
    res = score(saved, loader, precision, device_of(cfg["accelerator"]),
                per_recording=split == "test", observers=observers,
                limit=limit_batches or 0, progress=not quiet)
    return EvalResult(task=saved.task, model=saved.model, split=split,
                      metrics=res["metrics"], checkpoint=Path(ckpt), config=cfg,
                      clips=res["clips"], recordings=res["recordings"],
                      per_recording=res["per_recording"])


def breakdown(run, data=None, *, which: str = "best", save: bool = False, **options) -> dict:
    """Scores the test split of run directory or checkpoint ``run`` like :func:`evaluate`
    (``options``: its keywords) and returns the breakdown document of
    :func:`bsp_fast.training.eval_breakdown.build_breakdown` (tables per joint, size or
    distance bin, profile, missing-joint count; counts that add up to ``totals``), with
    ``checkpoint``, ``model`` and the run's overall ``metrics``. ``save=True`` also
    writes it to ``RUN/test_breakdown.json`` (a run directory is needed)."""
    from ..reporting.breakdown import to_json
    from .eval_breakdown import BreakdownCollector, build_breakdown
    from .runs import BREAKDOWN_FILE as FILE

    run_dir = None
    if save:
        run_dir = resolve_checkpoint(run, which)[1]
        if run_dir is None:
            raise RunError(f"{run}: --save writes {FILE} into a run directory; this "
                           "checkpoint has none")
    collector = BreakdownCollector()
    res = evaluate(run, "test", data, which=which, observers=[collector], **options)
    doc = build_breakdown(collector, res.task, res.metrics)
    doc.update(model=res.model, checkpoint=str(res.checkpoint))
    if save:
        from ..atomic import write_text

        write_text(Path(run_dir) / FILE, to_json(doc) + "\n")
    return doc


def _box_noise(text: str) -> tuple:
    try:
        scale, shift = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SCALE,SHIFT (e.g. 0.1,0.05), got {text!r}") \
            from None
    if not (0 <= scale <= 0.5 and 0 <= shift <= 0.5):
        raise argparse.ArgumentTypeError(f"SCALE and SHIFT must lie in [0, 0.5], got {text!r}")
    return scale, shift


def _parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-eval",
        description="Re-evaluate a bsp-train checkpoint (bsp-eval RUN_OR_CKPT), or print "
                    "runs side by side in the report's table layout (bsp-eval --table "
                    "RUN...), with the initial-metrics row of the trivial baseline.",
        epilog="exit codes: 0 success, 1 bad data/run/checkpoint, 2 bad arguments. "
               "docs: docs/training.md", formatter_class=HelpFormatter)
    p.add_argument("runs", nargs="+", metavar="RUN_OR_CKPT",
                   help="a run directory or .ckpt (several with --table)")
    p.add_argument("--table", action="store_true",
                   help="print the runs' saved metrics side by side (one table per task)")
    p.add_argument("--format", default="markdown", choices=("markdown", "md", "csv", "json"),
                   help="table format (json: --breakdown only)")
    p.add_argument("--breakdown", action="store_true",
                   help="score the test split and print its metrics per joint, per pixel "
                        "height (2D) or camera distance (lifting) bin, per age/gender, per "
                        "realised missing-joint count, with counts (docs/training.md)")
    p.add_argument("--save", action="store_true",
                   help="--breakdown: also write RUN/test_breakdown.json")
    p.add_argument("--split", default="test", choices=tuple(SPLIT_STAGES),
                   help="split to evaluate (tables: val = the best epoch's val metrics)")
    p.add_argument("--which", default="best", choices=("best", "last"),
                   help="checkpoint of a run directory")
    p.add_argument("--data", default=None, metavar="DATASET_OR_H5",
                   help="data to evaluate on (default: the run's dataset folder, else its "
                        "HDF5 file)")
    p.add_argument("--box-noise", default=None, metavar="SCALE,SHIFT", type=_box_noise,
                   help="pose_estimation: score crops of noisy boxes, side x U[1-SCALE, "
                        "1+SCALE] and centre moved by U[-SHIFT, SHIFT] x side (e.g. 0.1,0.05), "
                        "seeded per clip; needs a file with context crops")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the metrics here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--print-config", action="store_true",
                   help="print the run's config with the options given here applied (YAML, "
                        "usable as bsp-train --config) and exit")
    # how the run is scored: bsp-train's own declarations (training/config.py, scoring=True)
    p.set_defaults(overrides=add_overrides(p, "scoring"))
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    return run_command("bsp-eval", _main, args)


def _main(args) -> int:
    if args.table:
        from ..reporting.run_tables import runs_table
        from .runs import read_finished
        from .tasks import TABLE_COLUMNS

        if args.format == "json" or args.breakdown:
            raise C.ConfigError("--table prints markdown or csv, without --breakdown")
        print(runs_table(read_finished(args.runs, args.split), TABLE_COLUMNS,
                         "markdown" if args.format == "md" else args.format, args.split))
        return 0
    if len(args.runs) != 1:
        raise C.ConfigError("evaluate one run or checkpoint at a time (or use --table)")
    if args.format == "json" and not args.breakdown:
        raise C.ConfigError("--format json applies to --breakdown only")
    if args.save and not args.breakdown:
        raise C.ConfigError("--save writes the breakdown: add --breakdown")
    if args.print_config:
        cfg = run_config(args.runs[0], args.which, args.data,
                         **given_overrides(args, args.overrides))[0]
        print(C.dump(cfg), end="")
        return 0
    _check_outputs(args)
    if args.breakdown:
        return _print_breakdown(args)
    res = evaluate(args.runs[0], args.split, args.data, which=args.which, quiet=args.quiet,
                   box_noise=args.box_noise, **given_overrides(args, args.overrides))
    if args.json:
        write_json({"task": res.task, "model": res.model, "split": res.split,
                    "checkpoint": str(res.checkpoint), args.split: res.metrics}, args.json)
    from ..reporting.run_tables import scored_text

    print(scored_text(res, getattr(args, "limit_batches", None)))
    return 0


def _check_outputs(args) -> None:
    """The output rule (bsp_fast.atomic.check_outputs), before the run is loaded: --json
    (and, with --breakdown --save, RUN/test_breakdown.json) is none of the run's inputs
    (the run directory, its checkpoint and config.yaml, the data), nor each other."""
    from .runs import BREAKDOWN_FILE as FILE

    outputs = [("--json", args.json)]
    if args.breakdown and args.save:
        try:
            run_dir = resolve_checkpoint(args.runs[0], args.which)[1]
        except RunError:
            run_dir = None  # said when the run is loaded
        if run_dir is not None:
            outputs.append(("--save", Path(run_dir) / FILE))
    check_run_outputs(run_inputs(args.runs[0], args.which, args.data), outputs)


def _print_breakdown(args) -> int:
    from ..reporting.breakdown import format_breakdown, run_heading
    from .tasks import metric_formats

    if args.split != "test":
        raise C.ConfigError("--breakdown scores the test split; leave out --split")
    doc = breakdown(args.runs[0], args.data, which=args.which, save=args.save,
                    quiet=args.quiet, box_noise=args.box_noise,
                    **given_overrides(args, args.overrides))
    if args.json:
        write_json({"task": doc["task"], "model": doc["model"], "split": "test",
                    "checkpoint": doc["checkpoint"], "test": doc["metrics"]}, args.json)
    print(format_breakdown(doc, metric_formats(),
                           "md" if args.format == "markdown" else args.format,
                           heading=run_heading(doc)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
