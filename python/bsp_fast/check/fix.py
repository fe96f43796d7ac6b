"""``bsp-check --fix``: a cleaned copy of a dataset, never an edit of the original.

What is dropped: recordings with a breaking finding (missing, unreadable or too short
media, unsafe paths, ...) or whose pedestrian is never visible in the masks, with their
media files; rows repeating an earlier row's key; annotated rows with no pedestrian pixel
near the joints; media files no row references. Everything else is copied byte for byte
(data.csv keeps the original bytes of every kept line). ``bsp-check-fix.tsv`` in the copy
lists every dropped item and why. The copy is built in ``.OUT_DIR.tmp-*`` and renamed.
"""
from __future__ import annotations

import os
import shutil

import numpy as np

from ..atomic import atomic_output, check_outputs
from .core import dataset_paths, run_check
from .rows import MEDIA_SUFFIXES, event_camera_file

LOG_NAME = "bsp-check-fix.tsv"


def check_fix_output(root: str, out_dir) -> None:
    """The output rule of ``--fix`` (:func:`bsp_fast.atomic.check_outputs`): the copy is
    neither the dataset, nor inside it, nor a folder holding it (OutputOverlapError)."""
    check_outputs(inputs=[("the dataset", root)], outputs=[("--fix", out_dir)],
                  read_dirs=[("the dataset", root, None)])


def _out_dir(root: str, out_dir, force: bool) -> str:
    check_fix_output(root, out_dir)
    out = os.path.realpath(os.fspath(out_dir))
    if os.path.exists(out) and not force:
        raise FileExistsError(f"{out_dir} exists; pass force=True (--force) to replace it")
    return out


def fix_dataset(dataset, out_dir, *, threads: int | None = None, force: bool = False,
                link: bool = False, progress: bool = False) -> dict:
    """Checks ``dataset`` and writes the cleaned copy to ``out_dir``; returns the report
    with a ``fix`` section (counts, dropped items by reason, the log's path).

    ``link`` hard-links kept files instead of copying them (same bytes, no extra space;
    falls back to copying across file systems). Raises ValueError when ``out_dir`` is
    the dataset or overlaps it, FileExistsError when it exists and not ``force``.
    """
    root, csv = dataset_paths(dataset)
    out = _out_dir(root, out_dir, force)
    report, recs, table = run_check(dataset, threads=threads, progress=progress)
    if table is None:
        report["fix"] = None
        report["info"].append("--fix: nothing written, data.csv cannot be parsed")
        return report
    drop_row, log = _plan_rows(table, recs)
    keep_files, drop_files = _plan_files(root, csv, recs, drop_row, table, log)
    parent = os.path.dirname(out)
    os.makedirs(parent, exist_ok=True)
    with atomic_output(out, force=force, folder=True) as tmp_path:
        tmp = str(tmp_path)
        os.chmod(tmp, 0o755)
        _write_csv(csv, os.path.join(tmp, os.path.basename(csv)), table, drop_row)
        for rel in keep_files:
            _copy(os.path.join(root, rel), os.path.join(tmp, rel), link)
        _write_log(os.path.join(tmp, LOG_NAME), log)
    reasons: dict = {}
    for what, _, why in log:
        k = f"{what}: {why.split(':')[0]}"
        reasons[k] = reasons.get(k, 0) + 1
    dropped_recs = sum(1 for r in recs if r.broken or r.never_visible)
    report["fix"] = {
        "out_dir": out, "log": os.path.join(out, LOG_NAME),
        "rows_kept": int(np.count_nonzero(~drop_row)), "rows_dropped": int(drop_row.sum()),
        "recordings_kept": len(recs) - dropped_recs, "recordings_dropped": dropped_recs,
        "files_copied": len(keep_files) + 1, "files_dropped": len(drop_files),
        "dropped_by_reason": reasons, "linked": bool(link)}
    return report


def _row_name(table, row) -> str:
    return (f"line {int(table.lines[row])} ({table['id'][row]}, frame "
            f"{int(table['frame.idx'][row])})")


def _plan_rows(table, recs) -> tuple:
    """(drop mask over rows, log entries [(what, name, reason)])."""
    drop = np.zeros(len(table), bool)
    log = []
    for r in recs:
        if r.broken or r.never_visible:
            why = "; ".join(f"{k}: {m}" for k, m in r.problems) if r.broken else \
                "never_visible: the pedestrian is in no mask frame"
            log.append(("recording", f"{r.key} ({len(r.rows)} rows)", why))
            drop[r.rows] = True
            continue
        first = {}
        for row, f in zip(r.rows, r.frames):
            first.setdefault(int(f), row)
        for row in r.duplicates:
            drop[row] = True
            log.append(("row", _row_name(table, row), "duplicate_rows: repeats line "
                        f"{int(table.lines[first[int(table['frame.idx'][row])]])}"))
        for row in r.occluded:
            if not drop[row]:
                drop[row] = True
                log.append(("row", _row_name(table, row), "fully_occluded_rows: no "
                            "pedestrian pixel near the joints"))
    return drop, log


def _plan_files(root, csv, recs, drop_row, table, log) -> tuple:
    """(files to copy, files left out) as '/'-separated paths relative to the root."""
    kept_refs, dropped_refs, kept_ids = set(), set(), set()
    for r in recs:
        alive = not (r.broken or r.never_visible) and not drop_row[r.rows].all()
        (kept_refs if alive else dropped_refs).update((r.video, r.segmentation))
        if alive:
            kept_ids.add(r.id)
    csv_rel = os.path.relpath(csv, root).replace(os.sep, "/")
    keep, drop = [], []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for name in sorted(filenames):
            rel = os.path.relpath(os.path.join(dirpath, name), root).replace(os.sep, "/")
            if rel == csv_rel or rel == LOG_NAME:
                continue
            if not name.lower().endswith(MEDIA_SUFFIXES) or rel in kept_refs \
                    or event_camera_file(rel, kept_ids):
                keep.append(rel)
                continue
            drop.append(rel)
            why = "its recording was dropped" if rel in dropped_refs or \
                event_camera_file(rel, {r.id for r in recs}) else "no row references it"
            log.append(("file", rel, why))
    return keep, drop


def _write_csv(src: str, dst: str, table, drop_row: np.ndarray) -> None:
    """Copies the header and the physical lines of every kept row, bytes unchanged."""
    if not drop_row.any():
        shutil.copyfile(src, dst)
        return
    starts = np.asarray(table.lines, np.int64)
    n = len(starts)
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        r = -1  # the row the current line belongs to (-1: before the first row)
        for line_no, line in enumerate(fin, start=1):
            while r + 1 < n and starts[r + 1] <= line_no:
                r += 1
            if r < 0 or not drop_row[r]:
                fout.write(line)


def _copy(src: str, dst: str, link: bool) -> None:
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    if link:
        try:
            os.link(src, dst)
            return
        except OSError:
            pass
    shutil.copy2(src, dst)


def _write_log(path: str, log: list) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# bsp-check --fix: what the cleaned copy leaves out, and why\n")
        fh.write("what\tname\treason\n")
        for what, name, why in log:
            fh.write(f"{what}\t{name}\t{why}\n")
