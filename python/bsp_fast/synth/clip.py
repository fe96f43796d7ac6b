"""One clip: street, camera, walk, poses, rendering, media and the CSV columns.

Randomness: clip i draws from ``SeedSequence(seed, spawn_key=(1, i))`` and its street from
``SeedSequence(seed, spawn_key=(0, i // batch_size))``, so a clip's output depends on the
seed and its index only, never on the worker that makes it.

Precision: poses are computed in float64 and stored as float32. ``pose.camera`` is the
projection (in float64) of the float32-rounded ``pose.world`` through the float32-rounded
camera transform, so re-projecting the CSV's own numbers reproduces it to float32 rounding
of the pixel values (~1e-4 px).
"""
from __future__ import annotations

import os
import uuid
from dataclasses import dataclass, field

import numpy as np

from .. import geometry as geo
from .. import skeleton as sk
from . import body, gait, scene, walker
from .config import SynthConfig

CHUNK = 30  # frames rendered and encoded per batch (bounds memory at 1600x600)

# Blueprint ids drawn per (age, gender). CARLA 0.9.13's children are 0009-0014 and
# 0048-0049; the split by gender below is this generator's convention only.
MODELS = {
    ("adult", "female"): ["0001", "0002", "0003", "0004", "0005", "0006", "0007", "0008"],
    ("adult", "male"): ["0015", "0016", "0017", "0018", "0019", "0020", "0021", "0022"],
    ("child", "female"): ["0009", "0010", "0011", "0048"],
    ("child", "male"): ["0012", "0013", "0014", "0049"],
}


@dataclass
class ClipPlan:
    """Everything about a clip except the rendered media (cheap to compute)."""

    index: int
    id: str
    profile: object
    model: str
    stem: str
    speed: float
    street: scene.Street
    plan: walker.Plan
    path: walker.Path
    camera: np.ndarray  # (6,) float64
    relative: np.ndarray  # (F, 26, 6) float64
    world_tick: int
    rng_props: np.random.Generator
    rng_look: np.random.Generator
    columns: dict = field(default_factory=dict)


def clip_rngs(seed: int, index: int, batch_size: int):
    street_ss = np.random.SeedSequence(seed, spawn_key=(0, index // batch_size))
    clip_ss = np.random.SeedSequence(seed, spawn_key=(1, index))
    ids, plan, props, look = clip_ss.spawn(4)
    return (np.random.default_rng(street_ss), np.random.default_rng(ids),
            np.random.default_rng(plan), np.random.default_rng(props),
            np.random.default_rng(look))


def bone_scale(cfg: SynthConfig, index: int) -> float:
    """The walker's bone-length factor of clip ``index``: 1 without
    ``bone_length_variation``, else uniform in [1 - v, 1 + v], from a stream of its own
    (so the variation changes no other random draw of the clip)."""
    v = cfg.bone_length_variation
    if not v:
        return 1.0
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(2, index)))
    return float(1.0 + v * rng.uniform(-1.0, 1.0))


def clip_id(rng: np.random.Generator) -> str:
    """``<uuid4>-0`` from 16 seeded random bytes."""
    return f"{uuid.UUID(bytes=rng.bytes(16), version=4)}-0"


def _pick_profile(rng, cfg: SynthConfig):
    profiles = [p for p, _ in cfg.pedestrian_distributions]
    weights = np.array([w for _, w in cfg.pedestrian_distributions], float)
    return profiles[int(rng.choice(len(profiles), p=weights / weights.sum()))]


def plan_clip(cfg: SynthConfig, index: int, motion=None) -> ClipPlan:
    """Samples the street, walk, camera and relative poses of clip `index`."""
    rng_street, rng_id, rng, rng_props, rng_look = clip_rngs(cfg.seed, index, cfg.batch_size)
    cid = clip_id(rng_id)
    st = scene.sample_street(rng_street)
    prof = _pick_profile(rng, cfg)
    stem = sk.model_name(prof.age, prof.gender)
    mean, std = prof.crossing_speed
    speed = float(np.clip(rng.normal(mean, std), 0.3, 3.0))
    crossing = bool(rng.uniform() < cfg.crossing_probability)
    F = cfg.clip_length_in_frames
    h = gait.capsule_half_height(stem)
    pl = walker.plan_clip(rng, st, crossing, cfg.look_at_shift, cfg.parallel_max_distance)
    path = walker.simulate(pl, st, speed, F, cfg.fps, h, cfg.waypoint_radius, rng)
    offset = [rng.normal(m, s) for m, s in cfg.camera_position_distributions[0]]
    look = st.to_world(pl.look_at_sw[0], pl.look_at_sw[1], 0.0)
    cam = scene.look_at_camera(look, pl.lane_heading, np.array(offset))
    style = gait.GaitStyle.sample(rng)
    scale = bone_scale(cfg, index)
    if motion is None:
        rel = gait.walk(stem, speed, F, cfg.fps, style, scale)
    else:
        rel = motion.relative_poses(stem, F, cfg.fps, phase=style.phase, scale=scale)
    model = "walker.pedestrian." + str(rng.choice(MODELS[(prof.age, prof.gender)]))
    tick = int(rng.integers(2_000, 400_000))
    return ClipPlan(index, cid, prof, model, stem, speed, st, pl, path, cam, rel, tick,
                    rng_props, rng_look)


def pose_columns(cp: ClipPlan, cfg: SynthConfig) -> dict:
    """Per-frame arrays for every frame (annotation filter applied later)."""
    F = cp.relative.shape[0]
    M = gait.mesh_offset_transform(cp.stem)
    walker_tf = np.zeros((F, 6))
    walker_tf[:, :3] = cp.path.xyz
    walker_tf[:, 4] = cp.path.yaw
    component = geo.forward_kinematics(cp.relative, root=M)
    world = geo.to_world(component, walker_tf)
    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    world32, cam32 = f32(world), f32(cp.camera)
    uv = geo.project(world32[..., :3].astype(np.float64), cam32.astype(np.float64),
                     cfg.width, cfg.height, cfg.camera_fov)
    uv32 = f32(uv)
    uvd = uv32.astype(np.float64)
    inside = np.isfinite(uvd).all(-1) & (uvd[..., 0] >= 0) & (uvd[..., 0] <= cfg.width) & \
        (uvd[..., 1] >= 0) & (uvd[..., 1] <= cfg.height)
    return {
        "world": world, "walker": walker_tf,
        "frame.pedestrian.transform": f32(walker_tf),
        "frame.pedestrian.velocity": f32(cp.path.velocity),
        "frame.pedestrian.pose.world": world32,
        "frame.pedestrian.pose.component": f32(component),
        "frame.pedestrian.pose.relative": f32(cp.relative),
        "frame.pedestrian.is_crossing": cp.path.on_lane.copy(),
        "frame.pedestrian.pose.camera": uv32,
        "frame.pedestrian.pose.in_frame": geo.in_frame(uvd, cfg.width, cfg.height),
        # Rows exist only for frames where the pedestrian is in view: at least one joint
        # projects inside the image (the recorder's weak criterion of being "in view").
        "annotated": inside.any(-1),
    }


def csv_columns(cp: ClipPlan, cfg: SynthConfig, per_frame: dict, visible: np.ndarray) -> dict:
    """The 24 CSV columns (writer's names) for the annotated frames of the clip."""
    rows = np.flatnonzero(per_frame["annotated"])
    n = len(rows)
    spawn = np.zeros(6, np.float32)
    spawn[:3] = per_frame["frame.pedestrian.transform"][0, :3]
    rep = lambda v, dt=None: np.full(n, v, dtype=dt)  # noqa: E731
    cols = {
        "id": rep(cp.id, object),
        "world.map": rep(cfg.world_map, object),
        "camera.idx": rep(0, np.int64),
        "camera.transform": np.repeat(np.asarray(cp.camera, np.float32)[None], n, 0),
        "camera.width": rep(cfg.width, np.int64),
        "camera.height": rep(cfg.height, np.int64),
        "pedestrian.idx": rep(0, np.int64),
        "pedestrian.model": rep(cp.model, object),
        "pedestrian.age": rep(cp.profile.age, object),
        "pedestrian.gender": rep(cp.profile.gender, object),
        "pedestrian.spawn_point": np.repeat(spawn[None], n, 0),
        "frame.idx": rows.astype(np.int64),
        "camera.recording": rep(f"clips/{cp.id}-0.mp4", object),
        "camera.semantic_segmentation": rep(f"clips/{cp.id}-1.apng", object),
        "world.frame": (cp.world_tick + rows).astype(np.int64),
    }
    for k in ("frame.pedestrian.transform", "frame.pedestrian.velocity",
              "frame.pedestrian.pose.world", "frame.pedestrian.pose.component",
              "frame.pedestrian.pose.relative", "frame.pedestrian.is_crossing",
              "frame.pedestrian.pose.camera", "frame.pedestrian.pose.in_frame"):
        cols[k] = per_frame[k][rows]
    cols["frame.pedestrian.pose.in_segmentation"] = np.asarray(visible, bool)[rows]
    return cols


def build_scene(cp: ClipPlan) -> scene.SceneTables:
    cam_sw = cp.street.to_road(cp.camera[None, :2])[0]
    return scene.scene_tables(cp.rng_props, cp.street, cp.path.sw, cam_sw)


def _render_setup(cp: ClipPlan, cfg: SynthConfig, per_frame: dict, threads: int):
    """Background (RGB, tags, depth), body colours and per-frame capsules of the clip:
    everything render_bodies needs. Draws from the clip's props and look generators only."""
    from .._native import core

    tabs = build_scene(cp)
    bg = core.render_background(
        tabs.road, tabs.bands, tabs.boxes, tabs.cylinders, tabs.spheres, tabs.light,
        np.asarray(cp.camera, float), cfg.width, cfg.height, cfg.camera_fov, threads)
    colours = body.sample_colours(cp.rng_look)
    return tabs, bg, colours, _capsules(cp, per_frame)


def render_clip(cp: ClipPlan, cfg: SynthConfig, per_frame: dict, clips_dir: str,
                threads: int = 1) -> np.ndarray:
    """Renders every frame, writes ``<id>-0.mp4`` and ``<id>-1.apng``; returns visible[F]
    (the frame's segmentation holds tag 4)."""
    from .._native import core
    from ..media import ApngWriter, VideoWriter

    tabs, (bg_rgb, bg_tags, bg_depth), colours, caps = _render_setup(cp, cfg, per_frame,
                                                                     threads)
    W, H, fov = cfg.width, cfg.height, cfg.camera_fov
    F = caps.shape[0]
    visible = np.zeros(F, bool)
    base = os.path.join(clips_dir, cp.id)
    with VideoWriter(base + "-0.mp4", W, H, fps=cfg.fps, bitrate=cfg.video_bitrate,
                     preset=cfg.video_preset) as vw, \
            ApngWriter(base + "-1.apng", W, H, fps=cfg.fps,
                       drop_duplicates=cfg.apng_drop_duplicates) as aw:
        for f0 in range(0, F, CHUNK):
            rgb, tags, vis = core.render_bodies(bg_rgb, bg_tags, bg_depth,
                                                np.asarray(cp.camera, float), fov, tabs.light,
                                                np.ascontiguousarray(caps[f0:f0 + CHUNK]),
                                                colours, threads)
            vw.write(rgb)
            aw.write(tags)
            visible[f0:f0 + CHUNK] = vis
    return visible


def _capsules(cp: ClipPlan, per_frame: dict) -> np.ndarray:
    """The pedestrian's capsules (F, P, 7), world frame, every frame of the clip."""
    yaw = np.radians(cp.path.yaw)
    forward = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], -1)
    return body.body_capsules(per_frame["world"][..., :3], forward)


def segmentation_visibility(cp: ClipPlan, cfg: SynthConfig, per_frame: dict,
                            threads: int = 1) -> np.ndarray:
    """visible[F] as :func:`render_clip` returns it on the annotated frames (the only ones
    data.csv keeps; False elsewhere), without rendering, writing or encoding any image.

    ``core.body_visibility`` casts the same pixel rays through the same code as the two
    render passes, but only where a capsule is hit, with the street's depth of only those
    pixels (each cast once per clip) and each frame stopped at its first pedestrian
    pixel, so the flags are bit-for-bit those of the full mode (tests/python/
    test_synth_reference.py compares data.csv with 4fba854's, which rendered whole
    frames)."""
    from .._native import core

    F = per_frame["annotated"].shape[0]
    visible = np.zeros(F, bool)
    frames = np.flatnonzero(per_frame["annotated"])
    if len(frames) == 0:
        return visible
    tabs = build_scene(cp)
    caps = np.ascontiguousarray(_capsules(cp, per_frame)[frames])
    visible[frames] = core.body_visibility(
        tabs.road, tabs.bands, tabs.boxes, tabs.cylinders, tabs.spheres, tabs.light,
        np.asarray(cp.camera, float), cfg.width, cfg.height, cfg.camera_fov, caps, threads)
    return visible
