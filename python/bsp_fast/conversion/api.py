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

import json
import math
import numbers
import sys
import threading
import time
import warnings
from pathlib import Path

from .._native import core as _core
from ..atomic import atomic_output
from ..defaults import CONVERT, CROP_BOXES
from . import report as _report
from .errors import UnusableConversion
from .inputs import dataset_csv, dataset_fov, poses_only, refuse_inputs_as_output

__all__ = ["convert", "conversion_settings", "clip_settings"]




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


def clip_settings(*, clip_length=None, clip_offset=None, eval_clip_offset=None,
                  min_video_length=None, label=CONVERT["label"], benchmark=False,
                  val_frac=CONVERT["val_frac"], test_frac=CONVERT["test_frac"],
                  seed=CONVERT["seed"], balance=False) -> dict:
    """bsp-convert's clip options (also bsp-interop's), validated and resolved: defaults
    from :data:`bsp_fast.defaults.CONVERT`, ``label_fraction`` of ``label``; raises
    ValueError listing what is allowed."""
    if clip_length is None:
        clip_length = CONVERT["benchmark_clip_length"] if benchmark else CONVERT["clip_length"]
    if clip_offset is None:
        clip_offset = CONVERT["benchmark_clip_offset"] if benchmark else clip_length
    for name, v in (("clip_length", clip_length), ("clip_offset", clip_offset),
                    ("eval_clip_offset", eval_clip_offset), ("min_video_length", min_video_length)):
        _positive(name, v)
    for name, v in (("val_frac", val_frac), ("test_frac", test_frac)):
        if not (isinstance(v, (int, float)) and 0 <= v < 1):
            raise ValueError(f"{name} must lie in [0, 1), got {v!r}")
    if val_frac + test_frac >= 1:
        raise ValueError("val_frac + test_frac must be below 1")
    if not isinstance(seed, numbers.Integral) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    return dict(clip_length=clip_length, clip_offset=clip_offset,
                eval_clip_offset=eval_clip_offset or clip_offset,
                min_video_length=min_video_length or clip_length, label=label,
                label_fraction=_label_fraction(label), benchmark=bool(benchmark),
                val_frac=val_frac, test_frac=test_frac, seed=int(seed), balance=bool(balance))


def conversion_settings(dataset, *, clip_length=None, clip_offset=None, eval_clip_offset=None,
                        fov=None, min_video_length=None, label=CONVERT["label"], benchmark=False,
                        val_frac=CONVERT["val_frac"], test_frac=CONVERT["test_frac"],
                        seed=CONVERT["seed"], balance=False, compress=False, media=None,
                        crop_size=CONVERT["crop_size"], skip_bad_media=False,
                        crop_box=CONVERT["crop_box"],
                        crop_context=CONVERT["crop_context"]) -> dict:
    """The validated, fully resolved options that decide what :func:`convert` writes (the
    ``settings`` of its report and the ``settings_json`` attribute of the file): defaults
    filled in, the FOV looked up in the dataset's config.yaml, ``media`` None: on unless
    config.yaml says the dataset has none (``poses_only: true``). Raises ValueError."""
    root, _ = dataset_csv(dataset)
    media = _media(root, media)
    clip = clip_settings(clip_length=clip_length, clip_offset=clip_offset,
                         eval_clip_offset=eval_clip_offset, min_video_length=min_video_length,
                         label=label, benchmark=benchmark, val_frac=val_frac,
                         test_frac=test_frac, seed=seed, balance=balance)
    clip.pop("label_fraction")
    if not isinstance(crop_size, int) or isinstance(crop_size, bool) or not 8 <= crop_size <= 1024:
        raise ValueError(f"crop_size must be an integer in [8, 1024], got {crop_size!r}")
    if crop_box not in CROP_BOXES:
        raise ValueError(f"crop_box must be one of {', '.join(CROP_BOXES)}, got {crop_box!r}")
    if (isinstance(crop_context, bool) or not isinstance(crop_context, (int, float))
            or not 1 <= crop_context <= 4):
        raise ValueError(f"crop_context must be a number in [1, 4], got {crop_context!r}")
    fov_source = "argument"
    if fov is None:
        fov, fov_source = dataset_fov(root), "config.yaml"
        if fov is None:
            fov, fov_source = CONVERT["fov"], "default"
    if not (0 < float(fov) < 180):
        raise ValueError(f"fov must lie in (0, 180) degrees, got {fov!r}")
    return dict(**clip, fov=float(fov), fov_source=fov_source,
                compress=bool(compress), media=bool(media),
                crop_size=int(crop_size) if media else None,
                crop_box=crop_box if media else None,
                crop_context=float(crop_context) if media else None,
                skip_bad_media=bool(skip_bad_media) if media else None)


def _media(root, media):
    """``media`` resolved: None follows the dataset's config.yaml (a ``--poses-only``
    dataset has no MP4/APNG files); asking for the media of such a dataset is an error."""
    if media is not None and not media:
        return False  # no media asked for: config.yaml is not read for it
    none = poses_only(root)
    if media is None:
        return not none
    if none:
        raise ValueError(f"{Path(root) / 'config.yaml'} says poses_only: true (the dataset has "
                         "no MP4/APNG files); convert it without the media (--no-media, "
                         "media=False)")
    return bool(media)


def convert(dataset, out_path, *, clip_length=None, clip_offset=None, eval_clip_offset=None,
            fov=None, min_video_length=None, label=CONVERT["label"], benchmark=False,
            val_frac=CONVERT["val_frac"], test_frac=CONVERT["test_frac"], seed=CONVERT["seed"],
            balance=False, threads=None, verify=False, compress=False, media=None,
            crop_size=CONVERT["crop_size"], skip_bad_media=False, force=False,
            progress=None, strict=False, client=None, shards=None,
            crop_box=CONVERT["crop_box"], crop_context=CONVERT["crop_context"]) -> dict:
    """Converts a CARLA-BSP dataset (its directory or its data.csv) into train/val/test
    clips in one HDF5 file, written under a temporary name and renamed when complete (an
    existing ``out_path`` is kept unless ``force``); returns the report: rows, recordings,
    clips per split and class, skipped recordings and why, seconds per stage, ``media``,
    ``warnings``, ``settings`` and, with ``verify``, the verification table. The keywords
    are bsp-convert's options; what each does and its default: docs/convert.md, "The
    keywords of bsp_fast.convert". ``client`` (a ``distributed.Client``) converts on a
    Dask cluster instead, in ``shards`` tasks (docs/distributed.md)."""
    root, csv = dataset_csv(dataset)
    out = Path(out_path)
    refuse_inputs_as_output(root, csv, out)
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass force=True (--force) to overwrite it")
    settings = conversion_settings(
        dataset, clip_length=clip_length, clip_offset=clip_offset,
        eval_clip_offset=eval_clip_offset, fov=fov, min_video_length=min_video_length,
        label=label, benchmark=benchmark, val_frac=val_frac, test_frac=test_frac, seed=seed,
        balance=balance, compress=compress, media=media, crop_size=crop_size,
        skip_bad_media=skip_bad_media, crop_box=crop_box, crop_context=crop_context)
    _positive("threads", threads)
    _positive("shards", shards)
    if shards is not None and client is None:
        raise ValueError("shards needs a client (a Dask cluster to run them on)")
    options = _core_options(settings, root, eval_clip_offset=eval_clip_offset,
                            min_video_length=min_video_length, label=label,
                            val_frac=val_frac, test_frac=test_frac, threads=threads,
                            verify=verify, crop_size=crop_size, skip_bad_media=skip_bad_media,
                            crop_box=crop_box, crop_context=crop_context)
    out.parent.mkdir(parents=True, exist_ok=True)
    report = _write(csv, root, out, options, client=client, shards=shards, strict=strict,
                    force=force, progress=_is_terminal(sys.stderr) if progress is None
                    else progress)
    report["settings"] = settings
    report["media"]["why_none"] = None if settings["media"] else (
        "the dataset's config.yaml says poses_only: true" if media is None else "media=False")
    for w in report["warnings"]:
        warnings.warn(f"bsp_fast.convert: {w} ({out})", UserWarning, stacklevel=2)
    return report


def _write(csv, root, out: Path, options: dict, *, client, shards, strict, force,
           progress) -> dict:
    """The conversion itself: on the Dask cluster of ``client``, or in this process into a
    temporary file renamed when complete (``strict``: nothing written for an unusable
    conversion); the report, its ``warnings`` said."""
    if client is not None:
        from .sharded import convert_sharded

        return convert_sharded(str(csv), out, options, client, shards=shards, strict=strict,
                               root=root, force=force)
    with atomic_output(out, force=force) as tmp:
        report = _run(str(csv), str(tmp), options, progress)
        report["warnings"] = _report.problems(report)
        if strict and report["warnings"]:
            raise UnusableConversion(f"{root}: unusable conversion (strict): "
                                     + "; ".join(report["warnings"]) + "; nothing written")
    report["output"] = str(out)
    return report


def _core_options(st: dict, root: Path, *, eval_clip_offset, min_video_length, label,
                  val_frac, test_frac, threads, verify, crop_size, skip_bad_media, crop_box,
                  crop_context) -> dict:
    """The core's conversion options from the resolved settings ``st`` (the file's
    ``settings_json`` attribute too)."""
    return dict(clip_length=st["clip_length"], clip_stride=st["clip_offset"],
                eval_clip_stride=eval_clip_offset or 0, min_video_length=min_video_length or 0,
                label_fraction=_label_fraction(label), benchmark=st["benchmark"],
                val_frac=float(val_frac), test_frac=float(test_frac), seed=st["seed"],
                balance=st["balance"], fov=st["fov"], threads=int(threads or 0),
                verify=bool(verify), compress=st["compress"], media=st["media"],
                crop_size=int(crop_size), skip_bad_media=bool(skip_bad_media),
                crop_box=crop_box, crop_context=float(crop_context),
                source_path=str(root.resolve()),
                extra_attrs={"settings_json": json.dumps(st, sort_keys=True)})


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
    bars = _report.ProgressBars(show_progress)
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
