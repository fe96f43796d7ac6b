"""``bsp-convert``: the command line of :func:`bsp_fast.convert`."""
from __future__ import annotations

import argparse
import re
import sys
import threading
import warnings

from .._native import core as _core
from ..command_line import EXIT, ArgumentParser, BadInput, HelpFormatter, run_command
from ..dask_cluster import SCHEDULER_HELP, run_on_scheduler
from ..defaults import CONVERT, CROP_BOXES
from .api import convert
from .report import format_report, verify_table

__all__ = ["main"]

#: the core's errors about a recording's MP4 or APNG (missing, unreadable, broken)
MEDIA_ERRORS = (_core.VideoDecodeError, _core.ApngError)


def _media_error(exc) -> bool:
    return isinstance(exc, MEDIA_ERRORS) or bool(re.search(r"\.(mp4|png|apng): ", str(exc)))


def _parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-convert",
        description="Convert a CARLA-BSP dataset (data.csv + clips/) into train/val/test clips "
                    "in one HDF5 file.",
        epilog="Exit codes (docs/architecture.md): 0 success, 1 bad input, I/O error, or "
               "(--strict) an unusable "
               "result, 2 bad arguments, 3 output exists (use --force), 4 --verify found "
               "recordings beyond tolerance, 130 interrupted.",
        formatter_class=HelpFormatter)
    p.add_argument("dataset", help="dataset directory holding data.csv (or the data.csv itself)")
    p.add_argument("output", help="HDF5 file to write (written to a temporary name, then renamed)")
    _clip_options(p)
    _media_options(p)
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    p.add_argument("--scheduler", default="threads", metavar="threads|dask|dask:ADDRESS",
                   help="where to convert: " + SCHEDULER_HELP + "; with dask, OUT is made of "
                        "virtual datasets over the folder OUT.shards, which must stay next to "
                        "it (docs/distributed.md)")
    p.add_argument("--shards", type=int, default=None, metavar="N",
                   help="with --scheduler dask: tasks (default: one per Dask worker); the "
                        "output does not depend on it")
    p.add_argument("--verify", action="store_true",
                   help="check relative/component/world columns agree (mm) and pose.camera "
                        "matches the projection of pose.world (px), per recording")
    p.add_argument("--strict", action="store_true",
                   help="an empty split or a split with a single class is an error (exit 1, "
                        "nothing written) instead of a warning")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars or summary (warnings are still printed); bars are "
                        "shown only when stderr is a terminal")
    return p


def _clip_options(p) -> None:
    """How clips are cut, labelled and split."""
    p.add_argument("--clip-length", type=int, default=None, metavar="L",
                   help=f"frames per clip (default {CONVERT['clip_length']}; "
                        f"{CONVERT['benchmark_clip_length']} with --benchmark)")
    p.add_argument("--clip-offset", type=int, default=None, metavar="N",
                   help="stride: frames between the first frames of consecutive train clips; "
                        f"overlap = L - N (default L, i.e. no overlap; {CONVERT['benchmark_clip_offset']} "
                        "with --benchmark)")
    p.add_argument("--eval-clip-offset", type=int, default=None, metavar="N",
                   help="the same stride for val/test clips (default: --clip-offset)")
    p.add_argument("--fov", type=float, default=None,
                   help="horizontal camera field of view in degrees (default: the dataset's "
                        f"config.yaml, else {CONVERT['fov']:g})")
    p.add_argument("--min-video-length", type=int, default=None, metavar="ROWS",
                   help="skip recordings with fewer annotated rows (default: L)")
    p.add_argument("--label", default=CONVERT["label"], metavar="last|any:F",
                   help="clip label: is_crossing of the last frame, or of any of the last "
                        "ceil(L*F) frames")
    p.add_argument("--benchmark", action="store_true",
                   help="time-to-event windows of the crossing benchmark (video-level labels; "
                        "16/6 clips). It does not balance the train split: add --balance for "
                        "the report's setup (BSPDataModule.benchmark() does both)")
    p.add_argument("--test-frac", type=float, default=CONVERT["test_frac"], metavar="F",
                   help="test split: F of ALL clips, rounded down, at least one (whole "
                        "recordings, so about F)")
    p.add_argument("--val-frac", type=float, default=CONVERT["val_frac"], metavar="F",
                   help="validation split: F of the clips LEFT AFTER the test split, rounded "
                        f"down, at least one (default {CONVERT['val_frac']:g}; with --test-frac 0.2 that is about "
                        "20%% test, 16%% val and 64%% train clips)")
    p.add_argument("--seed", type=int, default=CONVERT["seed"], help="seed of the split shuffle")
    p.add_argument("--balance", action="store_true",
                   help="balance the train split's classes (keep min class count of each)")


def _media_options(p) -> None:
    """What is stored besides the poses: compression, crops, masks."""
    p.add_argument("--compress", action="store_true",
                   help="shuffle+deflate the large target arrays and the RGB crops (smaller, "
                        "slower to read); the masks are always deflated")
    p.add_argument("--no-media", action="store_true",
                   help="skip the media: no crops, masks or joint visibility, no MP4/APNG "
                        "opened (a dataset whose config.yaml says poses_only: true, as "
                        "bsp-synth --poses-only writes, has none and converts without them)")
    p.add_argument("--crop-size", type=int, default=CONVERT["crop_size"], metavar="S",
                   help="side of the square pedestrian crops (RGB and class-tag mask) in pixels")
    p.add_argument("--crop-box", default=CONVERT["crop_box"], choices=CROP_BOXES,
                   help="what the crop box is made from: mask (the segmentation mask's box, "
                        "what a detector could see; frames without a pedestrian pixel get no "
                        "crop and are reported as fully occluded), mask+joints (union with the "
                        "ground-truth joint box: an upper bound) or joints")
    p.add_argument("--crop-context", type=float, default=CONVERT["crop_context"], metavar="F",
                   help="also store the crop box widened F times about its centre "
                        "(frames/context_rgb), from which box noise is cut; 1 = none")
    p.add_argument("--skip-bad-media", action="store_true",
                   help="leave out recordings whose MP4 or APNG is missing or broken (listed in "
                        "the summary) instead of failing")


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that the temporary output is removed."""

    code = 143


def _on_sigterm(signum, frame):
    raise _Terminated("terminated; no output written")


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    import signal

    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main else None
    try:
        return run_command("bsp-convert", _main, args)
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


def _main(args) -> int:
    from pathlib import Path

    from .inputs import dataset_csv, refuse_inputs_as_output

    try:  # before a cluster is started (convert() checks again)
        root, csv = dataset_csv(args.dataset)
        refuse_inputs_as_output(root, csv, Path(args.output))
    except FileNotFoundError:
        pass  # convert() says so
    return run_on_scheduler(args.scheduler, "bsp-convert", lambda c: _convert_cli(args, c))


def _convert_cli(args, client) -> int:
    if client is None and args.shards is not None:
        raise ValueError("--shards needs --scheduler dask")
    try:
        with warnings.catch_warnings():  # printed below, once, in the summary
            warnings.simplefilter("ignore", UserWarning)
            report = convert(
                args.dataset, args.output, clip_length=args.clip_length,
                clip_offset=args.clip_offset, eval_clip_offset=args.eval_clip_offset,
                fov=args.fov, min_video_length=args.min_video_length, label=args.label,
                benchmark=args.benchmark, val_frac=args.val_frac, test_frac=args.test_frac,
                seed=args.seed, balance=args.balance, threads=args.threads, verify=args.verify,
                compress=args.compress, media=False if args.no_media else None,
                crop_size=args.crop_size,
                skip_bad_media=args.skip_bad_media, force=args.force,
                crop_box=args.crop_box, crop_context=args.crop_context,
                progress=False if args.quiet else None, strict=args.strict, client=client,
                shards=args.shards)
    except (_Terminated, FileExistsError):
        raise
    except KeyboardInterrupt:
        raise KeyboardInterrupt("no output written") from None
    except (OSError, _core.Error) as exc:
        if _media_error(exc):
            raise BadInput(f"{type(exc).__name__}: {exc}; convert without the media "
                           "(--no-media) or leave such recordings out "
                           "(--skip-bad-media)") from exc
        raise
    if not args.quiet:
        print(format_report(report))
        if args.verify:
            print(verify_table(report))
        print(f"wrote {report['output']}")
    elif report["warnings"]:
        for w in report["warnings"]:
            print(f"bsp-convert: WARNING: {w}", file=sys.stderr)
    if args.verify and report["verify_failed"]:
        return EXIT["verify"]
    return EXIT["ok"]


if __name__ == "__main__":
    sys.exit(main())
