"""bsp_fast.synth.generate: a whole CARLA-BSP-format dataset, clip by clip.

Each clip is made by one worker (media written straight into the output tree, its CSV rows
into a per-clip part file); the parent appends the parts to data.csv in clip order. The
output is built in ``.OUT_DIR.tmp-*`` and renamed when complete, so an interrupted run never
leaves a half-written dataset under OUT_DIR. The same seed gives byte-identical files
whatever the number of workers.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import shutil
import sys
import time

from ..atomic import atomic_output
from .config import SynthConfig, load_yaml_config, make_config

PARTS = ".parts"


def _clip_job(cfg: SynthConfig, index: int, root: str, threads: int) -> dict:
    """Makes clip `index` under `root`; returns its statistics (runs in a worker)."""
    from ..csvio import write_csv
    from . import clip as cl
    from . import motion as mo

    motion = mo.load(cfg.motion, float(cfg.fps)) if cfg.motion else None
    cp = cl.plan_clip(cfg, index, motion)
    per_frame = cl.pose_columns(cp, cfg)
    # A walker that never enters the view has no row: writing its MP4/APNG would leave
    # files no row references (bsp-check: unreferenced_media), so it gets none.
    if cfg.poses_only or not per_frame["annotated"].any():
        visible = cl.segmentation_visibility(cp, cfg, per_frame, threads)
    else:
        visible = cl.render_clip(cp, cfg, per_frame, os.path.join(root, "clips"), threads)
    cols = cl.csv_columns(cp, cfg, per_frame, visible)
    write_csv(os.path.join(root, PARTS, f"{index:06d}.csv"), cols,
                    threads=1 if threads == 1 else None)
    annotated = per_frame["annotated"]
    return {
        "index": index, "id": cp.id, "profile": cp.profile.name, "crossing": cp.plan.crossing,
        "speed": cp.speed, "frames": int(len(annotated)), "annotated": int(annotated.sum()),
        "crossing_frames": int((annotated & per_frame["frame.pedestrian.is_crossing"]).sum()),
        "segmentation_frames": int((annotated & visible).sum()),
    }


def _append_part(out, part: str, header: bool) -> None:
    with open(part, "rb") as fh:
        first = fh.readline()
        if header:
            out.write(first)
        shutil.copyfileobj(fh, out, 1 << 20)


def _resolve(preset, clips, frames, size, fov, seed, config, motion,
             apng_drop_duplicates, poses_only=False, bone_length_variation=None) -> SynthConfig:
    overrides = load_yaml_config(config) if config else {}
    cli = dict(number_of_clips=clips, clip_length_in_frames=frames, camera_image_size=size,
               camera_fov=fov, seed=seed)
    overrides.update({k: v for k, v in cli.items() if v is not None})
    if apng_drop_duplicates:
        overrides["apng_drop_duplicates"] = True
    if poses_only:
        overrides["poses_only"] = True
    if bone_length_variation is not None:
        overrides["bone_length_variation"] = bone_length_variation
    if motion is not None:
        path = os.path.abspath(os.fspath(motion))
        if not os.path.isfile(path):
            raise FileNotFoundError(f"motion file not found: {motion}")
        overrides["motion"] = path
    cfg = make_config(preset, overrides)
    if cfg.motion:
        from dataclasses import replace

        from . import motion as mo

        cfg = replace(cfg, motion_sha256=mo.load(cfg.motion, float(cfg.fps)).sha256)
    return cfg


def _summary(cfg: SynthConfig, stats: list, seconds: float, out_dir: str) -> dict:
    per_profile: dict = {}
    for s in stats:
        p = per_profile.setdefault(s["profile"], {"clips": 0, "annotated_frames": 0,
                                                  "crossing_clips": 0})
        p["clips"] += 1
        p["annotated_frames"] += s["annotated"]
        p["crossing_clips"] += int(s["crossing"])
    annotated = sum(s["annotated"] for s in stats)
    crossing = sum(s["crossing_frames"] for s in stats)
    frames = sum(s["frames"] for s in stats)
    return {
        "out_dir": out_dir, "clips": len(stats), "frames": frames,
        "annotated_frames": annotated, "annotated_share": annotated / frames if frames else 0.0,
        "crossing_frames": crossing, "crossing_share": crossing / annotated if annotated else 0.0,
        "crossing_clips": sum(int(s["crossing"]) for s in stats),
        "recordings": sum(s["annotated"] > 0 for s in stats),
        "per_profile": dict(sorted(per_profile.items())), "seconds": seconds,
        "clips_per_second": len(stats) / seconds if seconds > 0 else 0.0,
        "ids": [s["id"] for s in stats], "seed": cfg.seed, "preset": cfg.preset,
        "poses_only": cfg.poses_only,
    }


def generate(out_dir, preset: str = "sample", *, clips: int | None = None,
             frames: int | None = None, size=None, fov: float | None = None,
             seed: int | None = None, workers: int | None = None, config=None, motion=None,
             apng_drop_duplicates: bool = False, poses_only: bool = False,
             bone_length_variation: float | None = None, force: bool = False,
             progress: bool = True, client=None) -> dict:
    """Generates a CARLA-BSP-format dataset under ``out_dir`` and returns a summary dict.

    preset: ``sample`` (20 clips x 150 frames, 640x240), ``medium`` or ``full`` (396 x 900,
        1600x600); see ``PRESETS`` and docs/synth.md.
    clips, frames, size ('WxH' or (W, H)), fov, seed: override the preset and the config.
    config: a YAML file with the original generator's keys (number_of_clips,
        clip_length_in_frames, pedestrian_distributions, camera_position_distributions,
        camera_fov, camera_image_size, batch_size, seed, ...).
    motion: a BVH / FBX / glTF animation retargeted onto the skeleton instead of the gait.
    workers: worker processes (default: CPU count, at most one per clip); the output does
        not depend on it.
    apng_drop_duplicates: drop identical consecutive segmentation frames (as the original
        writer did); default keeps one APNG frame per video frame.
    poses_only: write data.csv (byte-identical to a full run with the same options) and
        config.yaml (``poses_only: true``) but no MP4/APNG: the media paths stay in the
        CSV, ``clips/`` is not created. ``in_segmentation`` is still decided exactly, by
        casting only the pixel rays that hit the pedestrian on the annotated frames (and
        the street behind those pixels, once per clip); no frame is rendered or encoded.
    bone_length_variation: v in [0, 0.5): each walker's bone offsets are scaled by a seeded
        factor in [1 - v, 1 + v] (its own random stream: every other draw is unchanged), so
        the reference skeletons of the (age, gender) profiles are no longer exact; the
        CSV's relative, component and world poses stay consistent (an ablation knob).
    force: replace an existing ``out_dir``.
    client: a ``distributed.Client``: one Dask task per clip instead of worker processes
        (``workers`` is then ignored); ``out_dir`` must be on a filesystem the workers share.
        The output is byte-identical (docs/distributed.md).

    Summary keys: out_dir, clips, frames, annotated_frames, annotated_share,
    crossing_frames, crossing_share, crossing_clips, recordings (clips with a row: the
    walker of the others never enters the view, and they have no media files), per_profile {name: {clips,
    annotated_frames, crossing_clips}}, seconds, clips_per_second, ids, seed, preset,
    poses_only.
    """
    t0 = time.perf_counter()
    out_dir = os.path.abspath(os.fspath(out_dir))
    if os.path.exists(out_dir) and not force:
        raise FileExistsError(f"{out_dir} exists; pass force=True (--force) to replace it")
    if not isinstance(poses_only, bool):
        raise ValueError(f"poses_only: expected True or False, got {poses_only!r}")
    cfg = _resolve(preset, clips, frames, size, fov, seed, config, motion,
                   apng_drop_duplicates, poses_only, bone_length_variation)
    workers = _worker_count(workers, cfg.number_of_clips)
    stats = _write_dataset(cfg, out_dir, workers, progress, client, force)
    return _summary(cfg, stats, time.perf_counter() - t0, out_dir)


def _worker_count(workers, clips: int) -> int:
    """The worker processes: ``workers`` (default: the CPU count), at most one per clip."""
    if workers is None:
        workers = min(os.cpu_count() or 1, clips)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected a positive integer, got {workers!r}")
    return min(workers, clips)


def _write_dataset(cfg: SynthConfig, out_dir: str, workers: int, progress: bool, client,
                   force: bool) -> list:
    """Writes the clips, data.csv and config.yaml under a temporary name renamed to
    ``out_dir`` when complete; returns the clips' stats."""
    from .._version import __version__

    os.makedirs(os.path.dirname(out_dir), exist_ok=True)
    with atomic_output(out_dir, force=force, folder=True) as tmp_path:
        tmp = str(tmp_path)
        if not cfg.poses_only:
            os.makedirs(os.path.join(tmp, "clips"))
        os.makedirs(os.path.join(tmp, PARTS))
        stats = _run_clips(cfg, tmp, workers, progress, client)
        _write_config(cfg, tmp, __version__)
        shutil.rmtree(os.path.join(tmp, PARTS))
    return stats


def _write_config(cfg: SynthConfig, root: str, version: str) -> None:
    import yaml

    with open(os.path.join(root, "config.yaml"), "w", encoding="utf-8") as fh:
        yaml.safe_dump(cfg.to_yaml_dict(version), fh, sort_keys=False)


def _dask_clip_job(cfg: SynthConfig, index: int, root: str) -> dict:
    from ..dask_cluster import test_hook

    test_hook("clip", index)
    return _clip_job(cfg, index, root, 1)


def _progress_bar(n: int, progress: bool):
    """tqdm's bar on a terminal; off one (a log file, CI) plain lines in bsp-train's style,
    no carriage returns (``bsp_fast._plain_progress``)."""
    from .._plain_progress import PlainLines, is_terminal

    if progress and not is_terminal(sys.stderr):
        return PlainLines(n, "clips")
    from tqdm.auto import tqdm

    return tqdm(total=n, desc="clips", unit="clip", disable=not progress)


def _run_clips(cfg: SynthConfig, root: str, workers: int, progress: bool, client=None) -> list:
    """Runs every clip and appends its rows to data.csv in clip order as they complete."""
    n = cfg.number_of_clips
    done: dict = {}
    stats = []
    bar = _progress_bar(n, progress)
    with open(os.path.join(root, "data.csv"), "wb") as out:
        def flush():
            while len(stats) in done:
                i = len(stats)
                part = os.path.join(root, PARTS, f"{i:06d}.csv")
                _append_part(out, part, header=i == 0)
                os.remove(part)  # the disk holds data.csv and the parts in flight, not both
                stats.append(done.pop(i))

        if client is not None:
            import uuid

            from distributed import as_completed

            token = uuid.uuid4().hex
            futures = [client.submit(_dask_clip_job, cfg, i, root, pure=False,
                                     key=f"bsp-synth-clip-{i}-{token}") for i in range(n)]
            try:
                for fut in as_completed(futures):
                    s = fut.result()
                    done[s["index"]] = s
                    flush()
                    bar.update(1)
            except BaseException:
                client.cancel(futures)
                raise
        elif workers == 1:
            for i in range(n):
                done[i] = _clip_job(cfg, i, root, 0)  # one process: threads inside C++
                flush()
                bar.update(1)
        else:
            ctx = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
                futures = [pool.submit(_clip_job, cfg, i, root, 1) for i in range(n)]
                try:
                    for fut in cf.as_completed(futures):
                        s = fut.result()
                        done[s["index"]] = s
                        flush()
                        bar.update(1)
                except BaseException:
                    for f in futures:
                        f.cancel()
                    raise
    bar.close()
    return stats


def profile_counts(summary: dict) -> dict:
    """{profile: clips} from a summary (a convenience for reports and tests)."""
    return {k: v["clips"] for k, v in summary["per_profile"].items()}


__all__ = ["generate", "profile_counts"]
