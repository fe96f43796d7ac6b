"""``bsp-cache``: list and prune the converted files BSPDataModule (and so bsp-train,
bsp-eval, bsp-predict, bsp-reproduce) keeps for a dataset directory.

    bsp-cache ls [DATASET ...] [--cache-dir DIR]
    bsp-cache prune DATASET (--max-size SIZE | --keep N | --all) [--dry-run]
    bsp-cache where DATASET

Needs no PyTorch: it reads the files' settings with h5py only.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from ..command_line import ArgumentParser, run_command
from . import cache as C


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-cache",
        description="The converted HDF5 files that bsp-train and BSPDataModule cache per "
                    "dataset (one per set of conversion options: --clip-length, "
                    "--clip-offset, --balance, ...): where they are, how big, when last "
                    "used; remove the least recently used ones.",
        epilog="The cache of DATASET is DATASET/bsp_fast-cache when the dataset directory is "
               "writable, else $XDG_CACHE_HOME/bsp_fast/<name>-<hash> (~/.cache by default). "
               "Exit codes (docs/architecture.md): 0 done, 1 no such dataset or an unreadable "
               "cache, 2 bad arguments. docs: docs/data.md")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    ls = sub.add_parser("ls", help="list cached files, least recently used first",
                        description="List the cached files of each DATASET (none given: every "
                                    "cache under $XDG_CACHE_HOME/bsp_fast, the caches of "
                                    "read-only datasets), least recently used first.")
    ls.add_argument("datasets", nargs="*", metavar="DATASET",
                    help="dataset directory (or its data.csv)")
    pr = sub.add_parser("prune", help="remove least recently used files",
                        description="Remove the least recently used cached files of DATASET "
                                    "until the limits hold. A removed file is converted again "
                                    "on its next use.")
    pr.add_argument("datasets", nargs=1, metavar="DATASET",
                    help="dataset directory (or its data.csv)")
    pr.add_argument("--max-size", metavar="SIZE",
                    help="keep at most SIZE bytes (units k, M, G, T: e.g. 500M, 2G)")
    pr.add_argument("--keep", type=int, metavar="N", help="keep at most N files")
    pr.add_argument("--all", action="store_true", help="remove every cached file")
    pr.add_argument("--dry-run", action="store_true", help="say what would go; remove nothing")
    wh = sub.add_parser("where", help="print the cache folder of a dataset")
    wh.add_argument("datasets", nargs=1, metavar="DATASET")
    for s in (ls, pr, wh):
        s.add_argument("--cache-dir", metavar="DIR",
                       help="a cache folder given to BSPDataModule(cache_dir=...) instead of "
                            "the dataset's default")
    return p


def _folder(dataset, cache_dir) -> Path:
    if cache_dir:
        return Path(cache_dir)
    from ..conversion.inputs import dataset_csv

    root, _ = dataset_csv(dataset)
    return C.default_cache_dir(root)


def _options(settings) -> str:
    if not settings:
        return "(unreadable)"
    s = settings
    words = [f"L{s.get('clip_length')}", f"offset {s.get('clip_offset')}"]
    if s.get("eval_clip_offset") not in (None, s.get("clip_offset")):
        words.append(f"eval offset {s['eval_clip_offset']}")
    words += [k for k in ("benchmark", "balance") if s.get(k)]
    if s.get("media"):
        words.append(f"media {s.get('crop_size')}px")
    words += [f"label {s.get('label')}", f"seed {s.get('seed')}", f"fov {s.get('fov'):g}"
              if isinstance(s.get("fov"), (int, float)) else ""]
    return " ".join(w for w in words if w)


def list_folder(folder: Path, out=None) -> tuple:
    """Prints one cache folder (to ``out``, default the current ``sys.stdout``, looked up
    at the call: a default bound at import would keep a replaced stream); returns
    (files, bytes)."""
    out = sys.stdout if out is None else out
    entries = C.cache_entries(folder)
    total = sum(e["bytes"] for e in entries)
    print(f"{folder}: {len(entries)} file(s), {C.format_bytes(total)}", file=out)
    for e in entries:
        when = time.strftime("%Y-%m-%d %H:%M", time.localtime(e["last_used"]))
        print(f"  {when}  {C.format_bytes(e['bytes']):>8s}  {e['path'].name}  "
              f"({_options(e['settings'])})", file=out)
    return len(entries), total


def _xdg_folders() -> list:
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "bsp_fast"
    return sorted(p for p in base.iterdir() if p.is_dir()) if base.is_dir() else []


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "prune":
        chosen = [x for x in (args.max_size is not None, args.keep is not None, args.all) if x]
        if not chosen:
            parser.error("prune: say what to keep: --max-size SIZE, --keep N or --all")
        if args.all and len(chosen) > 1:
            parser.error("prune: --all removes everything; it takes no --max-size or --keep")
    return run_command("bsp-cache", _main, args)


def _main(args) -> None:
    if args.command == "ls":
        _list(args)
        return
    folder = _folder(args.datasets[0], args.cache_dir)
    if args.command == "where":
        print(folder)
        return
    limit = None if args.max_size is None else C.parse_bytes(args.max_size)
    removed = C.prune(folder, max_bytes=limit, keep=args.keep, dry_run=args.dry_run)
    verb = "would remove" if args.dry_run else "removed"
    for e in removed:
        print(f"{verb} {e['path'].name} ({C.format_bytes(e['bytes'])})")
    n, size = C.cache_usage(folder)
    if args.dry_run:
        size -= sum(e["bytes"] for e in removed)
        n -= len(removed)
    print(f"{folder}: {len(removed)} file(s) {verb}, "
          f"{C.format_bytes(sum(e['bytes'] for e in removed))}; {n} left, "
          f"{C.format_bytes(size)}")


def _list(args) -> None:
    """``bsp-cache ls``: the given datasets' caches, or every cache under
    $XDG_CACHE_HOME/bsp_fast."""
    if args.cache_dir:
        folders = [Path(args.cache_dir)]
    elif args.datasets:
        folders = [_folder(d, None) for d in args.datasets]
    else:
        folders = _xdg_folders()
        if not folders:
            print("bsp-cache: no cache under $XDG_CACHE_HOME/bsp_fast; give a DATASET to "
                  "see the cache inside it")
    for folder in folders:
        list_folder(folder)


if __name__ == "__main__":
    sys.exit(main())
