"""``bsp-convert``: a CARLA-BSP dataset (data.csv) -> train/val/test clips in one HDF5 file.

Terminology, used the same way in the CLI, the API and the HDF5 attributes:

* **clip length** ``L``: frames per clip.
* **clip offset** (a.k.a. stride): frames between the first frames of two consecutive clips
  of the same segment. ``offset = L`` gives back-to-back clips (no overlap); the overlap
  is ``L - offset`` frames. The HDF5 file stores it as ``clip_stride``.
* **eval clip offset**: the same for the val and test splits (default: the train offset),
  so evaluation windows need not overlap like training windows.
* **media**: per split, a frame table of S x S pedestrian crops (RGB from the MP4, class
  tags from the segmentation APNG) with mask statistics and per-joint visibility; every
  frame a clip uses is stored once and clips point into it (``clip_frames``). See
  docs/hdf5-schema.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
import time
from pathlib import Path

from ._native import core as _core

__all__ = ["convert", "main", "format_report", "frame_media", "crop_resize", "DEFAULTS"]

DEFAULTS = dict(clip_length=30, benchmark_clip_length=16, benchmark_clip_offset=6,
                val_frac=0.2, test_frac=0.2, seed=22742, fov=90.0)
_STAGES = ("reading data.csv", "planning clips", "verifying poses", "writing clips", "done",
           "checking media files", "cropping media frames")


def frame_media(tags, uv) -> dict:
    """The per-frame media values bsp-convert stores, for one segmentation frame.

    ``tags``: (H, W) uint8 class tags (tag 4 = pedestrian); ``uv``: (26, 2) projected
    joints in pixels. Returns ``crop_box`` (4,) float32 ``[u0, v0, u1, v1]`` (a square with
    integer edges, possibly past the image), ``mask_bbox`` (4,) int32 ``[u0, v0, u1, v1)``
    or all -1, ``visible_pixels`` (tag-4 pixel count) and ``joint_visible`` (26,) uint8.
    """
    import numpy as np

    tags = np.asarray(tags)
    if tags.dtype != np.uint8 or tags.ndim != 2:
        raise ValueError(f"tags must be an (H, W) uint8 array, got {tags.dtype} {tags.shape}")
    return _core.frame_media(tags, np.asarray(uv, np.float32))


def crop_resize(image, box, size: int, nearest: bool = False):
    """Cuts ``box`` (``crop_box`` of :func:`frame_media`) out of an (H, W[, C]) uint8 image,
    zero-padding what lies outside, and resizes it to ``size`` x ``size`` the way
    bsp-convert does (OpenCV INTER_AREA for pictures, INTER_NEAREST for class tags)."""
    import numpy as np

    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image.dtype}")
    _positive("size", size, allow_none=False)
    return _core.crop_resize(image, np.asarray(box, np.float32), int(size), bool(nearest))


def _dataset_csv(dataset) -> tuple[Path, Path]:
    p = Path(dataset)
    if p.is_dir():
        csv = p / "data.csv"
        if not csv.is_file():
            raise FileNotFoundError(f"{p}: not a CARLA-BSP dataset (no data.csv inside)")
        return p, csv
    if p.is_file():
        return p.parent, p
    raise FileNotFoundError(f"{p}: no such dataset directory or data.csv file")


def _dataset_fov(root: Path):
    """FOV from a bsp-synth config.yaml beside data.csv, if there is one."""
    cfg = root / "config.yaml"
    if not cfg.is_file():
        return None
    import yaml

    try:
        doc = yaml.safe_load(cfg.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError:
        return None
    for key in ("fov", "camera_fov"):
        if isinstance(doc.get(key), (int, float)):
            return float(doc[key])
    return None


def _label_fraction(label: str) -> float:
    if label == "last":
        return 0.0
    if label.startswith("any:"):
        try:
            f = float(label[4:])
        except ValueError:
            f = -1.0
        if 0.0 < f <= 1.0:
            return f
    raise ValueError(f"label must be 'last' or 'any:F' with 0 < F <= 1, got {label!r}")


def _positive(name, v, allow_none=True):
    if v is None and allow_none:
        return
    if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
        raise ValueError(f"{name} must be a positive integer, got {v!r}")


def convert(dataset, out_path, *, clip_length=None, clip_offset=None, eval_clip_offset=None,
            fov=None, min_video_length=None, label="last", benchmark=False, val_frac=0.2,
            test_frac=0.2, seed=22742, balance=False, threads=None, verify=False,
            compress=False, media=True, crop_size=128, skip_bad_media=False, force=False,
            progress=False) -> dict:
    """Converts a CARLA-BSP dataset into train/val/test clips in one HDF5 file.

    ``dataset`` is the dataset directory (or its data.csv). ``clip_length`` defaults to 30
    (16 with ``benchmark``), ``clip_offset`` to the clip length (6 with ``benchmark``),
    ``eval_clip_offset`` to ``clip_offset``. ``label`` is ``'last'`` (is_crossing of the
    last frame) or ``'any:F'`` (any of the last ceil(L*F) frames). ``benchmark`` selects the
    time-to-event windows with video-level labels. ``fov`` defaults to the dataset's
    config.yaml, else 90 degrees. The output is written under a temporary name and renamed
    when complete; an existing ``out_path`` is kept unless ``force``.

    ``media`` (default on) decodes each recording's MP4 and segmentation APNG once and
    stores ``crop_size`` x ``crop_size`` pedestrian crops (RGB and class tags), mask
    statistics and joint visibility of every frame the clips use. A missing or broken media
    file fails the conversion naming the file, unless ``skip_bad_media``: then its
    recording is left out (the split is planned without it) and listed in
    ``report["media"]["bad"]``. Media paths in data.csv that are absolute or leave the
    dataset root (``..``) are refused before anything is opened. ``compress`` deflates the
    large pose targets and the RGB crops (about 2.5x smaller, much slower random reads).

    Returns the report: rows, recordings, clips per split and class, skipped recordings
    and why, seconds per stage, ``media`` (frames per split, seconds, crops_per_second,
    bad files and why) and, with ``verify``, the verification table.
    """
    root, csv = _dataset_csv(dataset)
    out = Path(out_path)
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass force=True (--force) to overwrite it")
    if clip_length is None:
        clip_length = DEFAULTS["benchmark_clip_length"] if benchmark else DEFAULTS["clip_length"]
    if clip_offset is None:
        clip_offset = DEFAULTS["benchmark_clip_offset"] if benchmark else clip_length
    for name, v in (("clip_length", clip_length), ("clip_offset", clip_offset),
                    ("eval_clip_offset", eval_clip_offset), ("min_video_length", min_video_length),
                    ("threads", threads)):
        _positive(name, v)
    if not isinstance(crop_size, int) or isinstance(crop_size, bool) or not 8 <= crop_size <= 1024:
        raise ValueError(f"crop_size must be an integer in [8, 1024], got {crop_size!r}")
    for name, v in (("val_frac", val_frac), ("test_frac", test_frac)):
        if not (isinstance(v, (int, float)) and 0 <= v < 1):
            raise ValueError(f"{name} must lie in [0, 1), got {v!r}")
    if val_frac + test_frac >= 1:
        raise ValueError("val_frac + test_frac must be below 1")
    fov_source = "argument"
    if fov is None:
        fov, fov_source = _dataset_fov(root), "config.yaml"
        if fov is None:
            fov, fov_source = DEFAULTS["fov"], "default"
    if not (0 < float(fov) < 180):
        raise ValueError(f"fov must lie in (0, 180) degrees, got {fov!r}")
    settings = dict(clip_length=clip_length, clip_offset=clip_offset,
                    eval_clip_offset=eval_clip_offset or clip_offset,
                    min_video_length=min_video_length or clip_length, label=label,
                    benchmark=bool(benchmark), val_frac=val_frac, test_frac=test_frac,
                    seed=int(seed), balance=bool(balance), fov=float(fov), fov_source=fov_source,
                    compress=bool(compress), media=bool(media),
                    crop_size=int(crop_size) if media else None,
                    skip_bad_media=bool(skip_bad_media) if media else None)
    options = dict(clip_length=clip_length, clip_stride=clip_offset,
                   eval_clip_stride=eval_clip_offset or 0, min_video_length=min_video_length or 0,
                   label_fraction=_label_fraction(label), benchmark=bool(benchmark),
                   val_frac=float(val_frac), test_frac=float(test_frac), seed=int(seed),
                   balance=bool(balance), fov=float(fov), threads=int(threads or 0),
                   verify=bool(verify), compress=bool(compress), media=bool(media),
                   crop_size=int(crop_size), skip_bad_media=bool(skip_bad_media),
                   source_path=str(root.resolve()),
                   extra_attrs={"settings_json": json.dumps(settings, sort_keys=True)})
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    try:
        report = _run(str(csv), str(tmp), options, progress)
        os.replace(tmp, out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    report["output"] = str(out)
    report["settings"] = settings
    return report


def _run(csv: str, tmp: str, options: dict, show_progress: bool) -> dict:
    """Runs the C++ conversion in a thread (GIL released) and polls its progress."""
    prog = _core.ConvertProgress()
    result: dict = {}

    def work():
        try:
            result["report"] = _core.convert_csv(csv, tmp, prog, **options)
        except BaseException as exc:  # re-raised in the calling thread
            result["error"] = exc

    t = threading.Thread(target=work, name="bsp-convert", daemon=True)
    t0 = time.perf_counter()
    t.start()
    bar, stage = None, -1
    try:
        while t.is_alive():
            t.join(0.1)
            if not show_progress:
                continue
            if prog.stage != stage:
                stage = prog.stage
                if bar is not None:
                    bar.close()
                bar = _bar(stage, prog.total)
            if bar is not None:
                bar.total = prog.total
                bar.n = prog.done
                bar.refresh()
    finally:
        if bar is not None:
            bar.close()
    if "error" in result:
        raise result["error"]
    report = result["report"]
    report["seconds"]["total"] = time.perf_counter() - t0
    media = report["media"]
    media["enabled"] = bool(options.get("media", True))
    frames = sum(media["frames"].values())
    decode = report["seconds"].get("media", 0.0)
    media["crops_per_second"] = frames / decode if decode > 0 else math.nan
    return report


def _bar(stage: int, total: int):
    from tqdm import tqdm

    name = _STAGES[min(stage, len(_STAGES) - 1)]
    if stage == 0:
        return tqdm(total=total, desc=name, unit="row", unit_scale=True, file=sys.stderr)
    if stage == 3:
        return tqdm(total=total, desc=name, unit="clip", file=sys.stderr)
    if stage == 5:
        return tqdm(total=total, desc=name, unit="recording", file=sys.stderr)
    if stage == 6:
        return tqdm(total=total, desc=name, unit="frame", file=sys.stderr)
    return None


def format_report(r: dict) -> str:
    """A plain-text summary table of a conversion report."""
    lines = [f"{'split':6s} {'clips':>7s} {'not-crossing':>13s} {'crossing':>9s} {'recordings':>11s}"]
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
    lines.append(f"read {sec.get('read', 0):.2f} s ({rate:,.0f} rows/s, "
                 f"{mb / max(sec.get('read', 1e-9), 1e-9):,.0f} MB/s), plan {sec.get('plan', 0):.2f} s, "
                 + (f"verify {sec['verify']:.2f} s, " if "verify" in sec else "")
                 + f"write {sec.get('write', 0):.2f} s, total {sec.get('total', 0):.2f} s")
    media = r.get("media", {})
    if media.get("enabled"):
        fr = media["frames"]
        lines.append(f"media: {sum(fr.values())} frames (train {fr['train']}, val {fr['val']}, "
                     f"test {fr['test']}), {sec.get('media', 0):.2f} s, "
                     f"{media['crops_per_second']:,.0f} crops/s, "
                     f"{len(media['bad'])} bad media files left out")
        for path, why in media["bad"][:20]:
            lines.append(f"  left out {path}: {why}")
    for rec, why in r["skipped"][:20]:
        lines.append(f"  skipped {rec}: {why}")
    if len(r["skipped"]) > 20:
        lines.append(f"  ... and {len(r['skipped']) - 20} more skipped recordings")
    return "\n".join(lines)


def _verify_table(r: dict) -> str:
    rows = sorted(r["verify"], key=lambda v: -max(v["component_mm"], v["world_mm"]))
    out = [f"{'recording':60s} {'component mm':>13s} {'world mm':>9s} {'camera px':>10s}"]
    for v in rows[:15]:
        out.append(f"{v['recording'][:60]:60s} {v['component_mm']:13.3f} {v['world_mm']:9.3f} "
                   f"{v['camera_px']:10.3f}")
    out.append(f"{len(r['verify_failed'])} of {len(rows)} recordings beyond tolerance")
    out += [f"  beyond tolerance: {name}" for name in r["verify_failed"][:50]]
    return "\n".join(out)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bsp-convert",
        description="Convert a CARLA-BSP dataset (data.csv + clips/) into train/val/test clips "
                    "in one HDF5 file. Exit codes: 0 success, 1 bad input or I/O error, 2 bad "
                    "arguments, 3 output exists (use --force), 4 --verify found recordings "
                    "beyond tolerance, 130 interrupted.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("dataset", help="dataset directory holding data.csv (or the data.csv itself)")
    p.add_argument("output", help="HDF5 file to write (written to a temporary name, then renamed)")
    p.add_argument("--clip-length", type=int, default=None, metavar="L",
                   help="frames per clip (default 30; 16 with --benchmark)")
    p.add_argument("--clip-offset", type=int, default=None, metavar="N",
                   help="stride: frames between the first frames of consecutive train clips; "
                        "overlap = L - N (default L, i.e. no overlap; 6 with --benchmark)")
    p.add_argument("--eval-clip-offset", type=int, default=None, metavar="N",
                   help="the same stride for val/test clips (default: --clip-offset)")
    p.add_argument("--fov", type=float, default=None,
                   help="horizontal camera field of view in degrees (default: the dataset's "
                        "config.yaml, else 90)")
    p.add_argument("--min-video-length", type=int, default=None, metavar="ROWS",
                   help="skip recordings with fewer annotated rows (default: L)")
    p.add_argument("--label", default="last", metavar="last|any:F",
                   help="clip label: is_crossing of the last frame, or of any of the last "
                        "ceil(L*F) frames")
    p.add_argument("--benchmark", action="store_true",
                   help="time-to-event windows of the crossing benchmark (video-level labels)")
    p.add_argument("--val-frac", type=float, default=0.2, help="share of clips for validation")
    p.add_argument("--test-frac", type=float, default=0.2, help="share of clips for testing")
    p.add_argument("--seed", type=int, default=22742, help="seed of the split shuffle")
    p.add_argument("--balance", action="store_true",
                   help="balance the train split's classes (keep min class count of each)")
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    p.add_argument("--compress", action="store_true",
                   help="shuffle+deflate the large target arrays and the RGB crops (smaller, "
                        "slower to read); the masks are always deflated")
    p.add_argument("--no-media", action="store_true",
                   help="skip the media: no crops, masks or joint visibility, no MP4/APNG opened")
    p.add_argument("--crop-size", type=int, default=128, metavar="S",
                   help="side of the square pedestrian crops (RGB and class-tag mask) in pixels")
    p.add_argument("--skip-bad-media", action="store_true",
                   help="leave out recordings whose MP4 or APNG is missing or broken (listed in "
                        "the summary) instead of failing")
    p.add_argument("--verify", action="store_true",
                   help="check relative/component/world columns agree (mm) and pose.camera "
                        "matches the projection of pose.world (px), per recording")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        report = convert(args.dataset, args.output, clip_length=args.clip_length,
                         clip_offset=args.clip_offset, eval_clip_offset=args.eval_clip_offset,
                         fov=args.fov, min_video_length=args.min_video_length, label=args.label,
                         benchmark=args.benchmark, val_frac=args.val_frac,
                         test_frac=args.test_frac, seed=args.seed, balance=args.balance,
                         threads=args.threads, verify=args.verify, compress=args.compress,
                         media=not args.no_media, crop_size=args.crop_size,
                         skip_bad_media=args.skip_bad_media, force=args.force,
                         progress=not args.quiet)
    except FileExistsError as exc:
        print(f"bsp-convert: {exc}", file=sys.stderr)
        return 3
    except ValueError as exc:
        print(f"bsp-convert: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("bsp-convert: interrupted; no output written", file=sys.stderr)
        return 130
    except (OSError, _core.Error) as exc:
        print(f"bsp-convert: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(format_report(report))
        if args.verify:
            print(_verify_table(report))
        print(f"wrote {report['output']}")
    if args.verify and report["verify_failed"]:
        return 4
    return 0


if __name__ == "__main__":
    sys.exit(main())
