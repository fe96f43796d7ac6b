"""Command line of bsp-check (console script ``bsp-check``)."""
from __future__ import annotations

import argparse
import sys

from ..atomic import DATASET_FILES, check_outputs
from ..command_line import EXIT, ArgumentParser, run_command


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-check",
        description="Check a CARLA-BSP dataset: files referenced by data.csv that are "
                    "missing and media files no row references; per recording the MP4 and "
                    "APNG frame counts against the largest frame.idx, rows whose "
                    "in_segmentation disagrees with the mask, recordings whose pedestrian is "
                    "never visible in the masks, annotated rows with no pedestrian pixel "
                    "near the joints, duplicate rows and gaps in frame.idx; and the "
                    "statistics table (scenes, annotated and crossing frames per age and "
                    "gender, annotated share). Each segmentation file is decoded once, files "
                    "spread over threads.",
        epilog="Exit codes (docs/architecture.md): 0 no errors (warnings alone, e.g. "
               "occluded rows, exit 0; --strict makes them 1), 1 errors found (or no such "
               "dataset, or data.csv unreadable), 2 bad arguments (--fix overlaps the "
               "dataset, --json or --fix is one of the dataset's files, or both are one "
               "path), 3 the --fix directory exists (--force replaces it), 130 interrupted. "
               "Gaps in frame.idx and event-camera files are notes, not problems.")
    p.add_argument("dataset", metavar="DATASET",
                   help="dataset directory holding data.csv (or the data.csv itself)")
    p.add_argument("--json", metavar="REPORT.json",
                   help="also write the full report (every finding with its data.csv lines, "
                        "the per-recording table, the statistics) as JSON")
    p.add_argument("--fix", metavar="OUT_DIR",
                   help="write a cleaned copy to OUT_DIR (never in place): without broken or "
                        "never-visible recordings, duplicate rows and fully occluded rows; "
                        "every kept file and data.csv line byte-identical; OUT_DIR/"
                        "bsp-check-fix.tsv lists what was dropped and why")
    p.add_argument("--link", action="store_true",
                   help="with --fix: hard-link the kept media files instead of copying them")
    p.add_argument("--force", action="store_true",
                   help="with --fix: replace OUT_DIR if it exists")
    p.add_argument("--threads", type=int, metavar="N",
                   help="files decoded at once (default: all cores)")
    p.add_argument("--strict", action="store_true",
                   help="warnings (fully occluded rows, never-visible pedestrians, "
                        "unreferenced media) fail too: exit 1")
    p.add_argument("--quiet", action="store_true",
                   help="print only the verdict line (and errors), no progress bar")
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if (args.link or args.force) and not args.fix:
        parser.error("--link and --force only apply with --fix")
    return run_command("bsp-check", _main, args)


def _main(args) -> int:
    from . import check_dataset, fix_dataset, format_report, to_json

    _check_outputs(args)
    if args.fix:
        report = fix_dataset(args.dataset, args.fix, threads=args.threads, force=args.force,
                             link=args.link, progress=not args.quiet)
    else:
        report = check_dataset(args.dataset, threads=args.threads, progress=not args.quiet)
    if args.json:
        to_json(report, args.json)
    text = format_report(report)
    if args.quiet:
        text = text.rstrip("\n").rsplit("\n", 1)[-1] + "\n"
    sys.stdout.write(text)
    return exit_code(report, args.strict)


def _check_outputs(args) -> None:
    """The output rule (bsp_fast.atomic.check_outputs), before any file is read: --fix is
    a separate copy (not the dataset, not inside it, not holding it); --json is none of
    the dataset's files (data.csv, config.yaml, media); the two are not one path."""
    from .core import dataset_paths
    from .fix import check_fix_output

    try:
        root, csv = dataset_paths(args.dataset)
    except FileNotFoundError:
        return  # said by the check itself
    if args.fix:
        check_fix_output(root, args.fix)
    check_outputs(inputs=[("the dataset's input", csv)],
                  outputs=[("--json", args.json), ("--fix", args.fix)],
                  read_dirs=[("the dataset", root, DATASET_FILES)])


def exit_code(report: dict, strict: bool = False) -> int:
    """0 without errors (and, with ``strict``, without warnings), else 1: warnings alone
    pass, as in linters and test runners."""
    failing = report["counts"]["error"] + (report["counts"]["warning"] if strict else 0)
    return EXIT["failure"] if failing else EXIT["ok"]


if __name__ == "__main__":
    sys.exit(main())
