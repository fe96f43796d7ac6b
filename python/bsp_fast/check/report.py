"""Text and JSON forms of a bsp-check report."""
from __future__ import annotations

import json
import os

import numpy as np

from ..atomic import write_text


def _plain(x):
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def to_json(report: dict, path=None) -> str:
    """The report as JSON text; with ``path``, also written there (atomically)."""
    text = json.dumps(_plain(report), indent=1) + "\n"
    if path is not None:
        write_text(path, text)
    return text


def _table(header: list, rows: list) -> list:
    cells = [[str(c) for c in header]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    out = []
    for k, r in enumerate(cells):
        out.append("  " + "  ".join(c.ljust(w) if i < 2 else c.rjust(w)
                                    for i, (c, w) in enumerate(zip(r, widths))).rstrip())
        if k == 0:
            out.append("  " + "  ".join("-" * w for w in widths))
    return out


def format_statistics(stats: dict) -> list:
    rows = [[p["age"], p["gender"], p["scenes"], p["frames"], p["crossing_frames"],
             f"{100 * p['crossing_share']:.1f} %"] for p in stats["per_profile"]]
    t = stats["total"]
    rows.append(["all", "", t["scenes"], t["frames"], t["crossing_frames"],
                 f"{100 * t['crossing_share']:.1f} %"])
    out = _table(["age", "gender", "scenes", "annotated frames", "crossing frames",
                  "crossing share"], rows)
    if stats["annotated_share"] is not None:
        out.append(f"  annotated share of frames: {t['frames']} / {stats['video_frames']} = "
                   f"{100 * stats['annotated_share']:.1f} % (frame totals from "
                   f"{stats['video_frames_from']})")
    return out


def _shown(path: str) -> str:
    """A path relative to the working directory when it lies below it."""
    rel = os.path.relpath(path)
    return path if rel.startswith("..") else rel


def format_report(report: dict, max_items: int = 20) -> str:
    """Human-readable summary: findings, notes, statistics and the verdict."""
    out = [f"bsp-check {_shown(report['dataset'])}"]
    if "rows" in report:
        n_media = report.get("media_files")
        out.append(f"data.csv: {report['rows']} rows, {len(report['recordings'])} recordings"
                   + (f"; {n_media} media files referenced" if n_media else "")
                   + f"; {report['seconds']['total']:.2f} s")
    findings = report["findings"]
    c = report["counts"]
    if findings:
        out.append(f"\nProblems: {c['error']} error(s), {c['warning']} warning(s)")
        for f in findings[:max_items]:
            where = f"  [{f['recording']}]" if f.get("recording") else ""
            out.append(f"  {f['severity']:7s} {f['kind']:25s} {f['message']}{where}")
        if len(findings) > max_items:
            out.append(f"  ... {len(findings) - max_items} more (see --json)")
    if report["info"]:
        out.append("\nNotes:")
        out += [f"  {x}" for x in report["info"][:max_items]]
        if len(report["info"]) > max_items:
            out.append(f"  ... {len(report['info']) - max_items} more (see --json)")
    if report.get("statistics"):
        out.append("\nStatistics (duplicate rows counted once):")
        out += format_statistics(report["statistics"])
    fix = report.get("fix")
    if fix:
        out.append(f"\nCleaned copy: {_shown(fix['out_dir'])}")
        out.append(f"  kept {fix['recordings_kept']} recordings, {fix['rows_kept']} rows, "
                   f"{fix['files_copied']} files; dropped {fix['recordings_dropped']} "
                   f"recordings, {fix['rows_dropped']} rows, {fix['files_dropped']} files "
                   f"(why: {_shown(fix['log'])})")
    if report["clean"]:
        verdict = "clean"
    elif c["error"] == 0:
        verdict = f"no errors, {c['warning']} warning(s) (--strict fails on warnings)"
    else:
        verdict = f"{len(findings)} problem(s) found"
    out.append("\nResult: " + verdict)
    return "\n".join(out) + "\n"
