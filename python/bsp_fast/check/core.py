"""``check_dataset``: every finding of bsp-check as one JSON-able report dict."""
from __future__ import annotations

import concurrent.futures as cf
import os
import time
from pathlib import Path

import numpy as np

from ..conversion.errors import BadDataset
from ..conversion.inputs import dataset_config
from .rows import (IN_SEG, event_camera_file, media_on_disk, read_table, recordings,
                   statistics)
from .scan import scan_entries, scan_job

#: Finding kinds: severity and whether --fix drops the whole recording for it.
KINDS = {
    "csv_unreadable": ("error", "data.csv cannot be parsed"),
    "unsafe_path": ("error", "a media path is absolute or leaves the dataset"),
    "inconsistent_recording": ("error", "rows of one recording disagree on files or size"),
    "negative_frame_idx": ("error", "frame.idx below 0"),
    "missing_file": ("error", "a file referenced by data.csv does not exist"),
    "unreadable_video": ("error", "the MP4 cannot be opened"),
    "unreadable_segmentation": ("error", "the APNG cannot be opened or decoded"),
    "size_mismatch": ("error", "media size differs from camera.width x camera.height"),
    "too_few_video_frames": ("error", "the MP4 ends before the largest frame.idx"),
    "too_short_segmentation": ("error", "the APNG ends before the largest frame.idx"),
    "duplicate_rows": ("error", "rows repeating (id, camera.idx, pedestrian.idx, frame.idx)"),
    "in_segmentation_mismatch": ("error", "in_segmentation disagrees with the mask"),
    "never_visible": ("warning", "the pedestrian is in no mask frame of the recording"),
    "fully_occluded_rows": ("warning", "annotated rows with no pedestrian pixel near the "
                                       "joints"),
    "unreferenced_media": ("warning", "a media file on disk that no row references"),
}
BREAKING = ("unsafe_path", "inconsistent_recording", "negative_frame_idx", "missing_file",
            "unreadable_video", "unreadable_segmentation", "size_mismatch",
            "too_few_video_frames", "too_short_segmentation")


def dataset_paths(dataset) -> tuple:
    """(root, data.csv) of a dataset directory or of its data.csv; FileNotFoundError."""
    p = Path(dataset)
    if p.is_dir():
        if not (p / "data.csv").is_file():
            raise FileNotFoundError(f"{p}: not a CARLA-BSP dataset (no data.csv inside)")
        return str(p), str(p / "data.csv")
    if p.is_file():
        return str(p.parent), str(p)
    raise FileNotFoundError(f"{p}: no such dataset directory or data.csv file")


def read_config(root: str) -> dict:
    """config.yaml beside data.csv, or {} (also when it is unreadable: the check reports
    on the data, bsp-convert on the file)."""
    try:
        return dataset_config(root)
    except BadDataset:
        return {}


def _finding(kind, message, recording=None, path=None, lines=None) -> dict:
    out = {"kind": kind, "severity": KINDS[kind][0], "message": message,
           "recording": recording, "path": path}
    if lines is not None:
        out["lines"] = [int(x) for x in lines]
    return out


def check_dataset(dataset, *, threads: int | None = None, progress: bool = False) -> dict:
    """Checks a CARLA-BSP dataset; returns the report (see docs/check.md).

    ``threads``: files decoded at once (default: ``bsp_fast.num_threads()``, all cores).
    Raises FileNotFoundError for a missing dataset and ValueError for a bad option; every
    problem of the data itself is a finding in the report, never an exception.
    """
    return run_check(dataset, threads=threads, progress=progress)[0]


def run_check(dataset, *, threads=None, progress=False) -> tuple:
    """(report, recordings, table) - what --fix needs besides the report."""
    from .._native import core

    num_threads = core.num_threads

    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise ValueError(f"threads must be None or a positive int, got {threads!r}")
    threads = threads or num_threads()
    root, csv = dataset_paths(dataset)
    config = read_config(root)
    poses_only = config.get("poses_only") is True
    fps = float(config["fps"]) if isinstance(config.get("fps"), (int, float)) else 30.0
    t0 = time.perf_counter()
    report = {"dataset": os.path.abspath(root), "csv": os.path.abspath(csv),
              "poses_only": poses_only, "fps": fps, "findings": [], "info": [],
              "recordings": [], "statistics": None, "seconds": {}}
    try:
        table = read_table(csv, threads)
    except Exception as e:  # noqa: BLE001 - CsvParseError, a missing column, ...
        report["findings"].append(_finding("csv_unreadable", f"{type(e).__name__}: {e}",
                                           path="data.csv"))
        return _finish(report, t0), [], None
    report["seconds"]["csv"] = time.perf_counter() - t0
    recs = recordings(table)
    report["rows"] = len(table)
    if poses_only:
        report["info"].append("poses-only dataset (config.yaml poses_only: true): data.csv "
                              "only; media files, frame counts and masks not checked")
    else:
        t1 = time.perf_counter()
        _check_media(root, table, recs, fps, threads, progress, report)
        report["seconds"]["media"] = time.perf_counter() - t1
    _row_findings(table, recs, report)
    n = config.get("clip_length_in_frames")
    report["statistics"] = statistics(table, recs, n if isinstance(n, int) and n > 0 else None)
    report["recordings"] = [_recording_entry(table, r) for r in recs]
    return _finish(report, t0), recs, table


def _finish(report: dict, t0: float) -> dict:
    report["seconds"]["total"] = time.perf_counter() - t0
    counts = {"error": 0, "warning": 0}
    for f in report["findings"]:
        counts[f["severity"]] += 1
    report["counts"] = counts
    report["clean"] = not report["findings"]
    return report


def _check_media(root, table, recs, fps, threads, progress, report) -> None:
    on_disk = media_on_disk(root)
    present = set(on_disk)
    referenced = set()
    for r in recs:
        referenced.update((r.video, r.segmentation))
        if r.broken:
            continue
        for p in (r.video, r.segmentation):
            if p not in present and not os.path.isfile(os.path.join(root, p)):
                r.problems.append(("missing_file", f"{p} does not exist"))
    report["media_files"] = len(referenced)
    ids = {r.id for r in recs}
    for p in on_disk:
        if p in referenced:
            continue
        if event_camera_file(p, ids):
            report["info"].append(f"{p}: event-camera output (no column references it)")
        else:
            report["findings"].append(_finding("unreferenced_media",
                                               f"{p}: no row references it", path=p))
    jobs = scan_entries(table, recs)
    results = _run_jobs(root, jobs, fps, threads, progress)
    by_index = {r.index: r for r in recs}
    for seg, entries in jobs.items():
        res = results[seg]
        for key, video, frames, *_ in entries:
            _merge(by_index[key], res, video, seg, frames)


def _run_jobs(root, jobs: dict, fps, threads, progress) -> dict:
    from tqdm.auto import tqdm

    results = {}
    bar = tqdm(total=len(jobs), desc="bsp-check", unit="file",
               disable=None if progress else True)
    with cf.ThreadPoolExecutor(max_workers=threads) as pool:
        futs = {pool.submit(scan_job, root, seg, entries, fps): seg
                for seg, entries in jobs.items()}
        for fut in cf.as_completed(futs):
            results[futs[fut]] = fut.result()
            bar.update(1)
    bar.close()
    return results


def _merge(r, res: dict, video: str, seg: str, frames: np.ndarray) -> None:
    v, s = res["videos"][video], res["segmentation"]
    last = int(frames.max()) if len(frames) else -1
    size = [r.width, r.height]
    if v["error"]:
        r.problems.append(("unreadable_video", f"{video}: {v['error']}"))
    else:
        r.video_frames = v["frames"]
        if v["size"] != size:
            r.problems.append(("size_mismatch", f"{video} is {v['size'][0]}x{v['size'][1]}, "
                                                f"data.csv says {size[0]}x{size[1]}"))
        if v["frames"] <= last:
            r.problems.append(("too_few_video_frames", f"{video} has {v['frames']} frames, "
                                                       f"data.csv annotates frame {last}"))
    if s["frames"] is not None:
        r.segmentation_frames = s["frames"]
        if s["size"] != size:
            r.problems.append(("size_mismatch", f"{seg} is {s['size'][0]}x{s['size'][1]}, "
                                                f"data.csv says {size[0]}x{size[1]}"))
        if s["covers"] is not None and s["covers"] <= last:
            r.problems.append(("too_short_segmentation", f"{seg} covers {s['covers']} video "
                                                         f"frames, data.csv annotates frame "
                                                         f"{last}"))
    if s["error"]:
        r.problems.append(("unreadable_segmentation", f"{seg}: {s['error']}"))
    r.mask_any, r.mask_near, r.scanned = res["rows"].get(r.index, (None, None, None))


def _row_findings(table, recs, report) -> None:
    lines = table.lines
    insg, valid = table[IN_SEG], table.valid(IN_SEG)
    for r in recs:
        key = r.key
        for kind, msg in r.problems:
            report["findings"].append(_finding(kind, msg, recording=key))
        if len(r.duplicates):
            first = {}
            for row, f in zip(r.rows, r.frames):
                first.setdefault(int(f), int(lines[row]))
            dl = lines[r.duplicates]
            ex = ", ".join(f"line {int(lines[d])} repeats line "
                           f"{first[int(table['frame.idx'][d])]}" for d in r.duplicates[:3])
            report["findings"].append(_finding(
                "duplicate_rows", f"{len(dl)} duplicate row(s): {ex}"
                + (" ..." if len(dl) > 3 else ""), recording=key, lines=dl))
        if r.scanned is None or r.broken:
            continue
        dup = np.isin(r.rows, r.duplicates)
        seen = r.scanned & ~dup
        mis = seen & valid[r.rows] & (insg[r.rows] != r.mask_any)
        occ = seen & (r.mask_near == 0)
        r.mismatch, r.occluded = r.rows[mis], r.rows[occ]
        if mis.any():
            said = insg[r.mismatch]
            ex = ", ".join(f"line {int(lines[x])} frame {int(table['frame.idx'][x])} says "
                           f"{bool(s)}" for x, s in zip(r.mismatch[:3], said[:3]))
            report["findings"].append(_finding(
                "in_segmentation_mismatch", f"{int(mis.sum())} row(s) whose in_segmentation "
                f"disagrees with the mask: {ex}" + (" ..." if mis.sum() > 3 else ""),
                recording=key, lines=lines[r.mismatch]))
        if seen.any() and not (r.mask_near[seen] > 0).any():
            r.never_visible = True
            report["findings"].append(_finding(
                "never_visible", f"the pedestrian is visible in none of its {int(seen.sum())} "
                "annotated mask frames", recording=key))
        elif occ.any():
            ex = ", ".join(f"line {int(lines[x])} (frame {int(table['frame.idx'][x])})"
                           for x in r.occluded[:3])
            report["findings"].append(_finding(
                "fully_occluded_rows", f"{int(occ.sum())} annotated row(s) with no "
                f"pedestrian pixel near the joints: {ex}" + (" ..." if occ.sum() > 3 else ""),
                recording=key, lines=lines[r.occluded]))
        if r.segments > 1:
            report["info"].append(f"{key}: {r.segments} segments (gaps in frame.idx, "
                                  f"{r.missing_frames} frames without a row)")


def _recording_entry(table, r) -> dict:
    e = {"id": r.id, "camera_idx": r.camera_idx, "pedestrian_idx": r.pedestrian_idx,
         "video": r.video, "segmentation": r.segmentation, "rows": int(len(r.rows)),
         "first_frame": int(r.frames.min()) if len(r.frames) else None,
         "last_frame": int(r.frames.max()) if len(r.frames) else None,
         "segments": r.segments, "frames_without_row": r.missing_frames,
         "duplicate_rows": int(len(r.duplicates)), "video_frames": r.video_frames,
         "segmentation_frames": r.segmentation_frames,
         "in_segmentation_mismatches": int(len(r.mismatch)),
         "fully_occluded_rows": int(len(r.occluded)),
         "problems": [k for k, _ in r.problems]}
    if r.scanned is not None:
        e["rows_with_pedestrian_pixels"] = int(np.count_nonzero(r.mask_near > 0))
    e["status"] = ("broken" if r.broken else "never_visible" if r.never_visible else "ok")
    return e
