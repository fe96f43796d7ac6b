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
import warnings
from pathlib import Path

from ._native import core as _core
from .convert_inputs import BadDataset, _dataset_csv, _dataset_fov, _refuse_inputs_as_output
from ._dask import SCHEDULER_HELP, run_on_scheduler
from .convert_report import ProgressBars, format_report, problems, verify_table

__all__ = ["convert", "conversion_settings", "main", "format_report", "frame_media",
           "crop_resize", "DEFAULTS", "UnusableConversion"]

DEFAULTS = dict(clip_length=30, benchmark_clip_length=16, benchmark_clip_offset=6,
                val_frac=0.2, test_frac=0.2, seed=22742, fov=90.0)


class UnusableConversion(ValueError):
    """``strict=True`` and the conversion has an empty split or a single-class split."""


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


def conversion_settings(dataset, *, clip_length=None, clip_offset=None, eval_clip_offset=None,
                        fov=None, min_video_length=None, label="last", benchmark=False,
                        val_frac=0.2, test_frac=0.2, seed=22742, balance=False, compress=False,
                        media=True, crop_size=128, skip_bad_media=False) -> dict:
    """The validated, fully resolved options that decide what :func:`convert` writes (the
    ``settings`` of its report and the ``settings_json`` attribute of the file): defaults
    filled in, the FOV looked up in the dataset's config.yaml. Raises ValueError."""
    root, _ = _dataset_csv(dataset)
    if clip_length is None:
        clip_length = DEFAULTS["benchmark_clip_length"] if benchmark else DEFAULTS["clip_length"]
    if clip_offset is None:
        clip_offset = DEFAULTS["benchmark_clip_offset"] if benchmark else clip_length
    for name, v in (("clip_length", clip_length), ("clip_offset", clip_offset),
                    ("eval_clip_offset", eval_clip_offset), ("min_video_length", min_video_length)):
        _positive(name, v)
    if not isinstance(crop_size, int) or isinstance(crop_size, bool) or not 8 <= crop_size <= 1024:
        raise ValueError(f"crop_size must be an integer in [8, 1024], got {crop_size!r}")
    for name, v in (("val_frac", val_frac), ("test_frac", test_frac)):
        if not (isinstance(v, (int, float)) and 0 <= v < 1):
            raise ValueError(f"{name} must lie in [0, 1), got {v!r}")
    if val_frac + test_frac >= 1:
        raise ValueError("val_frac + test_frac must be below 1")
    _label_fraction(label)
    fov_source = "argument"
    if fov is None:
        fov, fov_source = _dataset_fov(root), "config.yaml"
        if fov is None:
            fov, fov_source = DEFAULTS["fov"], "default"
    if not (0 < float(fov) < 180):
        raise ValueError(f"fov must lie in (0, 180) degrees, got {fov!r}")
    return dict(clip_length=clip_length, clip_offset=clip_offset,
                eval_clip_offset=eval_clip_offset or clip_offset,
                min_video_length=min_video_length or clip_length, label=label,
                benchmark=bool(benchmark), val_frac=val_frac, test_frac=test_frac,
                seed=int(seed), balance=bool(balance), fov=float(fov), fov_source=fov_source,
                compress=bool(compress), media=bool(media),
                crop_size=int(crop_size) if media else None,
                skip_bad_media=bool(skip_bad_media) if media else None)


def convert(dataset, out_path, *, clip_length=None, clip_offset=None, eval_clip_offset=None,
            fov=None, min_video_length=None, label="last", benchmark=False, val_frac=0.2,
            test_frac=0.2, seed=22742, balance=False, threads=None, verify=False,
            compress=False, media=True, crop_size=128, skip_bad_media=False, force=False,
            progress=None, strict=False, client=None, shards=None) -> dict:
    """Converts a CARLA-BSP dataset into train/val/test clips in one HDF5 file.

    ``dataset`` is the dataset directory (or its data.csv). ``clip_length`` defaults to 30
    (16 with ``benchmark``), ``clip_offset`` to the clip length (6 with ``benchmark``),
    ``eval_clip_offset`` to ``clip_offset``. ``label`` is ``'last'`` (is_crossing of the
    last frame) or ``'any:F'`` (any of the last ceil(L*F) frames). ``benchmark`` selects the
    time-to-event windows with video-level labels (it does not balance: add ``balance``).
    The split is by recording: ``test_frac`` of all clips go to test, then ``val_frac`` of
    the clips that remain go to validation (each at least one clip, whole recordings), so
    the defaults give about 20 % test and 16 % validation clips. ``fov`` defaults to the
    dataset's config.yaml, else 90 degrees. The output is written under a temporary name
    and renamed when complete; an existing ``out_path`` is kept unless ``force``.

    ``media`` (default on) decodes each recording's MP4 and segmentation APNG once and
    stores ``crop_size`` x ``crop_size`` pedestrian crops (RGB and class tags), mask
    statistics and joint visibility of every frame the clips use. A missing or broken media
    file fails the conversion naming the file, unless ``skip_bad_media``: then its
    recording is left out (the split is planned without it) and listed in
    ``report["media"]["bad"]``. Media paths in data.csv that are absolute or leave the
    dataset root (``..``) are refused before anything is opened. ``compress`` deflates the
    large pose targets and the RGB crops (about 2.5x smaller, much slower random reads).

    ``progress`` (default: when stderr is a terminal) shows a bar per stage. An empty split
    or a split with a single class is listed in ``report["warnings"]`` and warned about
    (``UserWarning``); ``strict`` raises :class:`UnusableConversion` instead and writes
    nothing.

    Returns the report: rows, recordings, clips per split and class, skipped recordings
    and why, seconds per stage, ``media`` (frames per split, seconds, crops_per_second,
    bad files and why), ``warnings``, ``settings`` and, with ``verify``, the verification
    table.

    ``client`` (a ``distributed.Client``) converts on a Dask cluster instead: ``shards``
    tasks (default: one per worker), each writing part of the output into the folder
    ``<out_path>.shards``, and ``out_path`` made of HDF5 virtual datasets over them, equal
    value for value to the one-process output (docs/distributed.md).
    """
    root, csv = _dataset_csv(dataset)
    out = Path(out_path)
    _refuse_inputs_as_output(root, csv, out)
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass force=True (--force) to overwrite it")
    settings = conversion_settings(
        dataset, clip_length=clip_length, clip_offset=clip_offset,
        eval_clip_offset=eval_clip_offset, fov=fov, min_video_length=min_video_length,
        label=label, benchmark=benchmark, val_frac=val_frac, test_frac=test_frac, seed=seed,
        balance=balance, compress=compress, media=media, crop_size=crop_size,
        skip_bad_media=skip_bad_media)
    _positive("threads", threads)
    _positive("shards", shards)
    if shards is not None and client is None:
        raise ValueError("shards needs a client (a Dask cluster to run them on)")
    if progress is None:
        progress = _is_terminal(sys.stderr)
    st = settings
    options = dict(clip_length=st["clip_length"], clip_stride=st["clip_offset"],
                   eval_clip_stride=eval_clip_offset or 0, min_video_length=min_video_length or 0,
                   label_fraction=_label_fraction(label), benchmark=st["benchmark"],
                   val_frac=float(val_frac), test_frac=float(test_frac), seed=st["seed"],
                   balance=st["balance"], fov=st["fov"], threads=int(threads or 0),
                   verify=bool(verify), compress=st["compress"], media=st["media"],
                   crop_size=int(crop_size), skip_bad_media=bool(skip_bad_media),
                   source_path=str(root.resolve()),
                   extra_attrs={"settings_json": json.dumps(settings, sort_keys=True)})
    out.parent.mkdir(parents=True, exist_ok=True)
    if client is not None:
        from .convert_dask import convert_sharded

        report = convert_sharded(str(csv), out, options, client, shards=shards, strict=strict,
                                 root=root)
        report["settings"] = settings
        for w in report["warnings"]:
            warnings.warn(f"bsp_fast.convert: {w} ({out})", UserWarning, stacklevel=2)
        return report
    tmp = out.with_name(f".{out.name}.tmp-{os.getpid()}")
    try:
        report = _run(str(csv), str(tmp), options, progress)
        report["warnings"] = problems(report)
        if strict and report["warnings"]:
            raise UnusableConversion(f"{root}: unusable conversion (strict): "
                                     + "; ".join(report["warnings"]) + "; nothing written")
        os.replace(tmp, out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    report["output"] = str(out)
    report["settings"] = settings
    for w in report["warnings"]:
        warnings.warn(f"bsp_fast.convert: {w} ({out})", UserWarning, stacklevel=2)
    return report


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


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
    bars = ProgressBars(show_progress)
    try:
        while t.is_alive():
            t.join(0.1)
            if show_progress:
                stage, total, done = prog.stage, prog.total, prog.done
                if prog.stage == stage:  # a consistent snapshot (no stage change in between)
                    bars.poll(stage, total, done)
    except BaseException:  # Ctrl-C, SIGTERM: the C++ work stops and is joined before we leave
        prog.cancel()
        t.join()
        raise
    finally:
        bars.close(completed="report" in result)
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


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows "(default: X)" only where the option has a real default that the help text
    does not already explain."""

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default is None or action.default is False or "default" in text:
            return text
        return super()._get_help_string(action)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bsp-convert",
        description="Convert a CARLA-BSP dataset (data.csv + clips/) into train/val/test clips "
                    "in one HDF5 file.",
        epilog="Exit codes: 0 success, 1 bad input, I/O error, or (--strict) an unusable "
               "result, 2 bad arguments, 3 output exists (use --force), 4 --verify found "
               "recordings beyond tolerance, 130 interrupted.",
        formatter_class=_HelpFormatter)
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
                   help="time-to-event windows of the crossing benchmark (video-level labels; "
                        "16/6 clips). It does not balance the train split: add --balance for "
                        "the report's setup (BSPDataModule.benchmark() does both)")
    p.add_argument("--test-frac", type=float, default=0.2, metavar="F",
                   help="test split: F of ALL clips, rounded down, at least one (whole "
                        "recordings, so about F)")
    p.add_argument("--val-frac", type=float, default=0.2, metavar="F",
                   help="validation split: F of the clips LEFT AFTER the test split, rounded "
                        "down, at least one (default 0.2; with --test-frac 0.2 that is about "
                        "20%% test, 16%% val and 64%% train clips)")
    p.add_argument("--seed", type=int, default=22742, help="seed of the split shuffle")
    p.add_argument("--balance", action="store_true",
                   help="balance the train split's classes (keep min class count of each)")
    p.add_argument("--threads", type=int, default=None, help="worker threads (default: all cores)")
    p.add_argument("--scheduler", default="threads", metavar="threads|dask|dask:ADDRESS",
                   help="where to convert: " + SCHEDULER_HELP + "; with dask, OUT is made of "
                        "virtual datasets over the folder OUT.shards, which must stay next to "
                        "it (docs/distributed.md)")
    p.add_argument("--shards", type=int, default=None, metavar="N",
                   help="with --scheduler dask: tasks (default: one per Dask worker); the "
                        "output does not depend on it")
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
    p.add_argument("--strict", action="store_true",
                   help="an empty split or a split with a single class is an error (exit 1, "
                        "nothing written) instead of a warning")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bars or summary (warnings are still printed); bars are "
                        "shown only when stderr is a terminal")
    return p


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that the temporary output is removed."""


def _on_sigterm(signum, frame):
    raise _Terminated()


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    import signal

    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main else None
    try:
        return _main(args)
    except _Terminated:
        print("bsp-convert: terminated; no output written", file=sys.stderr)
        return 143
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


def _main(args) -> int:
    return run_on_scheduler(args.scheduler, "bsp-convert", lambda c: _convert_cli(args, c))


def _convert_cli(args, client) -> int:
    if client is None and args.shards is not None:
        print("bsp-convert: --shards needs --scheduler dask", file=sys.stderr)
        return 2
    try:
        with warnings.catch_warnings():  # printed below, once, in the summary
            warnings.simplefilter("ignore", UserWarning)
            report = convert(
                args.dataset, args.output, clip_length=args.clip_length,
                clip_offset=args.clip_offset, eval_clip_offset=args.eval_clip_offset,
                fov=args.fov, min_video_length=args.min_video_length, label=args.label,
                benchmark=args.benchmark, val_frac=args.val_frac, test_frac=args.test_frac,
                seed=args.seed, balance=args.balance, threads=args.threads, verify=args.verify,
                compress=args.compress, media=not args.no_media, crop_size=args.crop_size,
                skip_bad_media=args.skip_bad_media, force=args.force,
                progress=False if args.quiet else None, strict=args.strict, client=client,
                shards=args.shards)
    except FileExistsError as exc:
        print(f"bsp-convert: {exc}", file=sys.stderr)
        return 3
    except (UnusableConversion, BadDataset) as exc:
        print(f"bsp-convert: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:
        print(f"bsp-convert: {exc}", file=sys.stderr)
        return 2
    except _Terminated:
        raise
    except KeyboardInterrupt:
        print("bsp-convert: interrupted; no output written", file=sys.stderr)
        return 130
    except (OSError, _core.Error) as exc:
        print(f"bsp-convert: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(format_report(report))
        if args.verify:
            print(verify_table(report))
        print(f"wrote {report['output']}")
    elif report["warnings"]:
        for w in report["warnings"]:
            print(f"bsp-convert: WARNING: {w}", file=sys.stderr)
    if args.verify and report["verify_failed"]:
        return 4
    return 0


if __name__ == "__main__":
    sys.exit(main())
