"""What ``bsp-convert`` tells its user: progress bars while it runs, the checks of an
unusable result, and the summary tables afterwards."""
from __future__ import annotations

import math
import sys

from .._native import core as _core

__all__ = ["ProgressBars", "problems", "format_report", "verify_table"]

_Stage = _core.ConvertStage
# The stages that get a bar: its label and what done/total count.
_BARS = {_Stage.read: ("reading data.csv", "row"), _Stage.write: ("writing clips", "clip"),
         _Stage.check_media: ("checking media files", "recording"),
         _Stage.media: ("cropping media frames", "frame")}


class ProgressBars:
    """One tqdm bar per stage of the C++ conversion, fed by polling its counters.

    ``poll(stage, total, done)`` takes one consistent snapshot (``stage``: a
    ``_core.ConvertStage``, or its integer value). A bar starts at the count
    its stage had already reached when first seen (so the rate only counts what it watched
    happen), advances with ``update`` (so tqdm's rate is items per second of wall time), and
    is filled to its total when its stage ends: a finished stage never shows less than
    100 %.
    """

    def __init__(self, enabled: bool, file=None):
        self.enabled, self.file = bool(enabled), file
        self.stage, self.bar = None, None

    def poll(self, stage, total: int, done: int) -> None:
        if not self.enabled:
            return
        stage = _Stage(int(stage))
        if stage != self.stage:
            self._finish()
            self.stage = stage
            if stage in _BARS:
                from tqdm import tqdm

                desc, unit = _BARS[stage]
                self.bar = tqdm(total=total, initial=min(done, total) if total else done,
                                desc=desc, unit=unit, unit_scale=stage == _Stage.read,
                                file=self.file or sys.stderr, dynamic_ncols=True)
            return
        if self.bar is not None:
            if total and total != self.bar.total:
                self.bar.total = total
            if done > self.bar.n:
                self.bar.update(done - self.bar.n)

    def _finish(self) -> None:
        if self.bar is not None:
            if self.bar.total and self.bar.n < self.bar.total:
                self.bar.update(self.bar.total - self.bar.n)
            self.bar.close()
        self.bar = None

    def close(self, completed: bool) -> None:
        """Ends the last bar: filled when the conversion completed, left as is otherwise."""
        if self.bar is not None and not completed:
            self.bar.close()
            self.bar = None
        self._finish()


def problems(report: dict) -> list:
    """What makes a conversion unusable for training or evaluation: an empty split, a split
    with a single class (no F1, no balancing), or no recording at all."""
    out = []
    splits = report.get("splits", {})
    for name in ("train", "val", "test"):
        s = splits.get(name)
        if s is None:
            continue
        if s["clips"] == 0:
            out.append(f"{name} split has no clips")
        elif min(s["not-crossing"], s["crossing"]) == 0:
            only = "crossing" if s["crossing"] else "not-crossing"
            out.append(f"{name} split has a single class: all {s['clips']} clips are {only}")
    if report.get("recordings", 1) == 0:
        out.append("no recording long enough to cut a clip from")
    return out


def format_report(r: dict) -> str:
    """A plain-text summary table of a conversion report (warnings first and last)."""
    lines = [f"{'split':6s} {'clips':>7s} {'not-crossing':>13s} {'crossing':>9s} "
             f"{'recordings':>11s}"]
    for name in ("train", "val", "test"):
        s = r["splits"][name]
        lines.append(f"{name:6s} {s['clips']:7d} {s['not-crossing']:13d} {s['crossing']:9d} "
                     f"{s['recordings']:11d}")
    sec = r["seconds"]
    rate = r["rows"] / sec["read"] if sec.get("read") else math.nan
    mb = r["source_bytes"] / 1e6
    lines.append(f"rows {r['rows']}, recordings {r['recordings']}, skipped {len(r['skipped'])}, "
                 f"windows outside the image {r['clips_rejected_out_of_image']}, "
                 f"dropped by balancing {r['clips_dropped_by_balance']}")
    mb_s = mb / max(sec.get("read", 1e-9), 1e-9)
    lines.append(f"read {sec.get('read', 0):.2f} s ({rate:,.0f} rows/s, {mb_s:,.0f} MB/s), "
                 f"plan {sec.get('plan', 0):.2f} s, "
                 + (f"verify {sec['verify']:.2f} s, " if "verify" in sec else "")
                 + f"write {sec.get('write', 0):.2f} s, total {sec.get('total', 0):.2f} s")
    media = r.get("media", {})
    if media.get("enabled"):
        fr = media["frames"]
        lines.append(f"media: {sum(fr.values())} frames (train {fr['train']}, val {fr['val']}, "
                     f"test {fr['test']}), {sec.get('media', 0):.2f} s, "
                     f"{media['crops_per_second']:,.0f} crops/s, "
                     f"{len(media['bad'])} bad media files left out")
        occ = media.get("fully_occluded")
        if occ is not None:
            lines.append(f"media: {sum(occ.values())} frames without a pedestrian pixel "
                         f"(fully occluded: train {occ['train']}, val {occ['val']}, "
                         f"test {occ['test']})"
                         + ("; no crop under --crop-box mask"
                            if r.get("settings", {}).get("crop_box") == "mask" else ""))
        for path, why in media["bad"][:20]:
            lines.append(f"  left out {path}: {why}")
    elif media.get("why_none"):
        lines.append(f"media: none ({media['why_none']}): no crops, masks or joint visibility")
    for rec, why in r["skipped"][:20]:
        lines.append(f"  skipped {rec}: {why}")
    if len(r["skipped"]) > 20:
        lines.append(f"  ... and {len(r['skipped']) - 20} more skipped recordings")
    for w in r.get("warnings", []):
        lines.append(f"WARNING: {w}")
    if r.get("warnings"):
        lines.append("WARNING: this output is not usable for training and evaluating a "
                     "classifier as it is (bsp-convert --strict makes this an error)")
    return "\n".join(lines)


def verify_table(r: dict) -> str:
    rows = sorted(r["verify"], key=lambda v: -max(v["component_mm"], v["world_mm"]))
    out = [f"{'recording':60s} {'component mm':>13s} {'world mm':>9s} {'camera px':>10s}"]
    for v in rows[:15]:
        out.append(f"{v['recording'][:60]:60s} {v['component_mm']:13.3f} {v['world_mm']:9.3f} "
                   f"{v['camera_px']:10.3f}")
    out.append(f"{len(r['verify_failed'])} of {len(rows)} recordings beyond tolerance")
    out += [f"  beyond tolerance: {name}" for name in r["verify_failed"][:50]]
    return "\n".join(out)
