"""The pedestrian's path: spawn on a sidewalk, the recorder's look-at point on the nearest
driving lane, then a constant-speed walk (docs/dataset-format.md,
"6. How the recorder placed cameras and walkers").

Crossing clips walk to the look-at point and keep going; the others walk up to
``parallel_max_distance`` metres parallel to the lane and keep going. A waypoint counts as
reached within ``waypoint_radius``. "Keep going" follows the last heading; like a CARLA
walker against a wall, a walker reaching the building line slides along it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import Street

TURN_RATE = 300.0  # deg/s: the walker turns quickly but not instantly towards a waypoint


@dataclass
class Plan:
    side: int  # -1 left, +1 right of the road (road frame)
    spawn_sw: np.ndarray  # (2,) road frame
    look_at_sw: np.ndarray  # (2,) on the lane centre
    lane_heading: float  # world yaw of the look-at lane's travel direction
    crossing: bool
    waypoints_sw: np.ndarray  # (k, 2)


@dataclass
class Path:
    sw: np.ndarray  # (F, 2) road-frame positions
    xyz: np.ndarray  # (F, 3) world capsule centre (ground + h)
    yaw: np.ndarray  # (F,) world yaw of the walker, degrees in (-180, 180]
    velocity: np.ndarray  # (F, 3) m/s
    on_lane: np.ndarray  # (F,) bool, inside a driving-lane polygon


def plan_clip(rng: np.random.Generator, st: Street, crossing: bool, shift: tuple,
              parallel_max: float) -> Plan:
    side = int(rng.choice([-1, 1]))
    inner, outer = st.sidewalk_bounds(side)
    spawn = np.array([rng.uniform(-8.0, 8.0), side * rng.uniform(inner + 0.45, outer - 0.35)])
    n_side = st.lanes[1] if side > 0 else st.lanes[0]
    lane_w = side * (n_side - 0.5) * st.lane_width  # nearest driving lane's centre
    # Shifted along the lane's travel direction (+s on the right side, -s on the left).
    look = np.array([spawn[0] + side * rng.normal(shift[0], shift[1]), lane_w])
    # Right-hand traffic: lanes at w > 0 run towards +s.
    lane_heading = st.heading + (0.0 if side > 0 else 180.0)
    if crossing:
        wps = look[None, :]
    else:
        dist = rng.uniform() * parallel_max
        direction = 1.0 if rng.uniform() < 0.5 else -1.0
        wps = (spawn + np.array([direction * dist, 0.0]))[None, :]
    return Plan(side, spawn, look, _wrap(lane_heading), crossing, wps)


def _wrap(deg):
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0


def simulate(plan: Plan, st: Street, speed: float, frames: int, fps: float, h: float,
             radius: float, rng: np.random.Generator) -> Path:
    """Integrates the walk tick by tick (frame 0 = spawn)."""
    dt = 1.0 / fps
    p = plan.spawn_sw.astype(float).copy()
    wps = list(plan.waypoints_sw)
    first = wps[0] - p
    heading = np.arctan2(first[1], first[0]) if np.hypot(*first) > 1e-9 else \
        (0.0 if rng.uniform() < 0.5 else np.pi)
    desired = heading
    wall = {s: st.building_line(s) - 0.35 for s in (-1, 1)}
    slide = None
    sw = np.empty((frames, 2))
    head = np.empty(frames)
    max_turn = np.radians(TURN_RATE) * dt
    for f in range(frames):
        sw[f], head[f] = p, heading
        while wps and np.hypot(*(wps[0] - p)) < radius:
            wps.pop(0)
        if wps:
            d = wps[0] - p
            desired = np.arctan2(d[1], d[0])
        step = speed * dt * np.array([np.cos(desired), np.sin(desired)])
        nxt_w = p[1] + step[1]
        if abs(nxt_w) > wall[1 if nxt_w > 0 else -1] and abs(nxt_w) > abs(p[1]) - 1e-9:
            if slide is None:  # blocked by the building line: slide along it
                slide = 0.0 if np.cos(desired) > 1e-6 else np.pi if np.cos(desired) < -1e-6 \
                    else (0.0 if rng.uniform() < 0.5 else np.pi)
            desired = slide
        turn = np.clip(_wrap_rad(desired - heading), -max_turn, max_turn)
        heading = heading + turn
        p = p + speed * dt * np.array([np.cos(heading), np.sin(heading)])
    ground = st.ground_height(sw[:, 1])
    xyz = st.to_world(sw[:, 0], sw[:, 1], ground + h)
    yaw = _wrap(st.heading + np.degrees(head))
    vel = np.gradient(xyz, dt, axis=0) if frames > 1 else np.zeros((frames, 3))
    return Path(sw, xyz, yaw, vel, st.on_driving_lane(sw[:, 1]))


def _wrap_rad(a):
    return (a + np.pi) % (2 * np.pi) - np.pi
