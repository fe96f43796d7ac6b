"""A procedural street in its own "road frame" (s along the road, w across it to the
right, z up; CARLA axes), placed in the world by a random heading and origin.

Cross-section from the centre line outwards on each side: driving lanes (right-hand
traffic: lanes at w > 0 run towards +s), an optional parking lane, a curb, the sidewalk,
a terrain verge, then buildings. Sidewalk, curb and verge are raised by ``CURB`` metres.
Props (parked cars, poles, signs, trees) are placed per clip, away from the pedestrian's
path. Every primitive becomes a row of the tables the C++ ray caster takes
(bsp_fast._core.render_background).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import rotation_matrix

CURB = 0.15  # height of curb, sidewalk and verge (m)
STREET_HALF_LENGTH = 220.0  # buildings and sidewalks cover s in [-L, L]

# CARLA 0.9.13 semantic tags (docs/dataset-format.md, "3. Media").
TAG = dict(building=1, fence=2, other=3, pedestrian=4, pole=5, road_line=6, road=7,
           sidewalk=8, vegetation=9, vehicle=10, wall=11, traffic_sign=12, sky=13,
           ground=14, static=19, dynamic=20, terrain=22)

BUILDING_COLOURS = np.array([[186, 170, 148], [150, 142, 135], [168, 96, 78], [205, 200, 190],
                             [120, 120, 128], [190, 160, 120], [140, 150, 160],
                             [175, 130, 100], [215, 210, 200], [98, 90, 85]], float)
CAR_COLOURS = np.array([[200, 200, 205], [30, 30, 35], [150, 20, 25], [20, 50, 120],
                        [230, 230, 230], [90, 95, 100], [180, 150, 40], [30, 90, 60],
                        [120, 60, 20]], float)


@dataclass
class Street:
    """Cross-section and placement of one street (metres, degrees)."""

    origin: tuple  # world (x, y) of the road frame origin
    heading: float  # world yaw of +s
    lane_width: float
    lanes: tuple  # (left, right) driving lanes; left ones run towards -s
    parking: tuple  # (left, right) parking-lane widths (0 = none)
    sidewalk: tuple  # (left, right) sidewalk widths, curb included
    verge: tuple  # (left, right) terrain widths before the buildings
    style: dict = field(default_factory=dict)  # colours, building seed, light

    # -- cross-section -----------------------------------------------------------------
    def driving_bounds(self) -> tuple:
        """(w_min, w_max) of the driving lanes."""
        return (-self.lanes[0] * self.lane_width, self.lanes[1] * self.lane_width)

    def road_edges(self) -> tuple:
        """(w_min, w_max) of the asphalt (driving + parking lanes): the curb lines."""
        lo, hi = self.driving_bounds()
        return (lo - self.parking[0], hi + self.parking[1])

    def sidewalk_bounds(self, side: int) -> tuple:
        """(inner, outer) |w| of the sidewalk on side -1 (left) or +1 (right)."""
        k = 0 if side < 0 else 1
        edge = abs(self.road_edges()[k])
        return (edge, edge + self.sidewalk[k])

    def building_line(self, side: int) -> float:
        """|w| where the buildings start on a side."""
        k = 0 if side < 0 else 1
        return self.sidewalk_bounds(side)[1] + self.verge[k]

    def ground_height(self, w) -> np.ndarray:
        """Walking surface height at lateral position(s) w: 0 on the asphalt, CURB beyond,
        with a 0.3 m step-down ramp at the curb so feet follow the surface smoothly."""
        w = np.asarray(w, float)
        lo, hi = self.road_edges()
        d = np.maximum(lo - w, w - hi)  # > 0 outside the asphalt
        return CURB * np.clip(d / 0.3 + 0.5, 0.0, 1.0)

    def on_driving_lane(self, w) -> np.ndarray:
        lo, hi = self.driving_bounds()
        w = np.asarray(w, float)
        return (w >= lo) & (w <= hi)

    # -- frames ------------------------------------------------------------------------
    def road_transform(self) -> np.ndarray:
        return np.array([self.origin[0], self.origin[1], 0.0, 0.0, self.heading, 0.0])

    def to_world(self, s, w, z=0.0) -> np.ndarray:
        """Road-frame points -> world (x, y, z); broadcasts."""
        c, sn = np.cos(np.radians(self.heading)), np.sin(np.radians(self.heading))
        s, w, z = np.broadcast_arrays(np.asarray(s, float), np.asarray(w, float),
                                      np.asarray(z, float))
        return np.stack([self.origin[0] + c * s - sn * w, self.origin[1] + sn * s + c * w, z],
                        axis=-1)

    def to_road(self, xyz) -> np.ndarray:
        """World points (..., 2 or 3) -> road-frame (s, w)."""
        xyz = np.asarray(xyz, float)
        c, sn = np.cos(np.radians(self.heading)), np.sin(np.radians(self.heading))
        dx, dy = xyz[..., 0] - self.origin[0], xyz[..., 1] - self.origin[1]
        return np.stack([c * dx + sn * dy, -sn * dx + c * dy], axis=-1)


def sample_street(rng: np.random.Generator) -> Street:
    """Random cross-section, placement and style. Multi-lane roads are common (the
    recordings come from Town04-like maps), so crossings take a while."""
    lanes_total = int(rng.choice([2, 3, 4, 4, 5, 6, 6, 8]))
    if lanes_total == 3 or lanes_total == 5:
        left = lanes_total // 2 + int(rng.integers(0, 2))
    else:
        left = lanes_total // 2
    lanes = (left, lanes_total - left)
    parking = tuple(float(rng.uniform(2.1, 2.6)) if rng.random() < 0.55 else 0.0
                    for _ in range(2))
    sidewalk = tuple(float(rng.uniform(2.0, 5.0)) for _ in range(2))
    verge = tuple(float(rng.choice([0.0, rng.uniform(1.0, 5.0)])) for _ in range(2))
    sun_el, sun_az = np.radians(rng.uniform(25, 70)), rng.uniform(0, 2 * np.pi)
    style = dict(
        asphalt=float(rng.uniform(70, 100)),
        line_colour=[240.0, 240.0, 235.0],
        centre_colour=([235.0, 200.0, 60.0] if rng.random() < 0.5 else [240.0, 240.0, 235.0]),
        sidewalk=(rng.uniform(150, 200) * np.array([1.0, 0.97, 0.93])).tolist(),
        grass=[float(rng.uniform(70, 110)), float(rng.uniform(110, 150)), 55.0],
        building_seed=int(rng.integers(0, 2**31 - 1)),
        sun=[float(np.cos(sun_el) * np.cos(sun_az)), float(np.cos(sun_el) * np.sin(sun_az)),
             float(np.sin(sun_el))],
        ambient=float(rng.uniform(0.42, 0.55)),
    )
    return Street(origin=(float(rng.uniform(-300, 300)), float(rng.uniform(-300, 300))),
                  heading=float(rng.uniform(-180, 180)), lane_width=float(rng.uniform(3.0, 3.7)),
                  lanes=lanes, parking=parking, sidewalk=sidewalk, verge=verge, style=style)


# ---------------------------------------------------------------------------------------
# Primitive tables (columns as documented in bsp_fast._core.render_background)

def _band(w0, w1, tag, rgb, period=0.0, on=0.0, phase=0.0, texture=0.0):
    return [w0, w1, tag, *rgb, period, on, phase, texture]


def _box(s0, w0, z0, s1, w1, z1, tag, rgb, pattern=0, texture=0.0):
    return [s0, w0, z0, s1, w1, z1, tag, *rgb, pattern, texture]


def ground_bands(st: Street) -> list:
    """Asphalt and markings on z = 0; everything else is terrain."""
    lw, (nl, nr) = st.lane_width, st.lanes
    lo, hi = st.driving_bounds()
    elo, ehi = st.road_edges()
    a = st.style["asphalt"]
    white, centre = st.style["line_colour"], st.style["centre_colour"]
    bands = [_band(-1e9, 1e9, TAG["terrain"], [96, 92, 70], texture=0.3),
             _band(elo, ehi, TAG["road"], [a, a, a * 1.02], texture=0.18)]
    if nl and nr:  # double centre line
        bands += [_band(-0.20, -0.08, TAG["road_line"], centre),
                  _band(0.08, 0.20, TAG["road_line"], centre)]
    for side, n in ((-1, nl), (1, nr)):
        for k in range(1, n):  # dashed dividers between lanes of one direction
            w = side * k * lw
            bands.append(_band(w - 0.07, w + 0.07, TAG["road_line"], white, 12.0, 3.0, 1.5))
    if not (nl and nr):
        bands.append(_band(-0.07, 0.07, TAG["road_line"], white))
    bands += [_band(lo + 0.05, lo + 0.2, TAG["road_line"], white),
              _band(hi - 0.2, hi - 0.05, TAG["road_line"], white)]
    return bands


def street_boxes(st: Street) -> list:
    """Curbs, sidewalks, verges and the building rows (style seeded per street)."""
    L = STREET_HALF_LENGTH
    rows = []
    brng = np.random.default_rng(st.style["building_seed"])
    for side in (-1, 1):
        k = 0 if side < 0 else 1
        inner, outer = st.sidewalk_bounds(side)
        line = st.building_line(side)
        curb_out = inner + 0.2
        lo_hi = lambda a, b: (min(side * a, side * b), max(side * a, side * b))  # noqa: E731
        w0, w1 = lo_hi(inner, curb_out)
        rows.append(_box(-L, w0, 0.0, L, w1, CURB, TAG["sidewalk"], [165, 165, 160], 0, 0.1))
        w0, w1 = lo_hi(curb_out, outer)
        rows.append(_box(-L, w0, 0.0, L, w1, CURB, TAG["sidewalk"], st.style["sidewalk"], 3, 0.12))
        if st.verge[k] > 0:
            w0, w1 = lo_hi(outer, line)
            rows.append(_box(-L, w0, 0.0, L, w1, CURB, TAG["terrain"], st.style["grass"], 0, 0.35))
        rows += _building_row(brng, side, line, L)
    return rows


def _building_row(rng, side: int, line: float, L: float) -> list:
    rows, s = [], -L
    while s < L:
        width = rng.uniform(8, 32)
        depth = rng.uniform(10, 25)
        height = rng.choice([rng.uniform(4, 9), rng.uniform(9, 20), rng.uniform(20, 45)],
                            p=[0.3, 0.5, 0.2])
        colour = BUILDING_COLOURS[rng.integers(len(BUILDING_COLOURS))] * rng.uniform(0.85, 1.1)
        setback = rng.choice([0.0, rng.uniform(0.5, 3.0)], p=[0.7, 0.3])
        a, b = side * (line + setback), side * (line + setback + depth)
        tag = TAG["building"] if rng.random() < 0.9 else TAG["wall"]
        rows.append(_box(s, min(a, b), 0.0, s + width, max(a, b), height, tag,
                         colour.tolist(), 1 if tag == TAG["building"] else 0, 0.12))
        s += width
        if rng.random() < 0.3:  # alley with a fence or a low wall across it
            gap = rng.uniform(3, 10)
            kind = TAG["fence"] if rng.random() < 0.5 else TAG["wall"]
            c, d = side * (line + 0.2), side * (line + 0.4)
            rows.append(_box(s, min(c, d), 0.0, s + gap, max(c, d), rng.uniform(1.0, 2.2), kind,
                             [110, 80, 70] if kind == TAG["fence"] else [150, 150, 160], 0, 0.2))
            s += gap
    return rows


# ---------------------------------------------------------------------------------------
# Props: placed per clip, kept clear of the walker's path

def _clear(path_sw: np.ndarray, s: float, w: float, radius: float) -> bool:
    if path_sw.size == 0:
        return True
    d2 = (path_sw[:, 0] - s) ** 2 + (path_sw[:, 1] - w) ** 2
    return bool(d2.min() > radius * radius)


def _clear_of_camera(cam_sw, s, w, radius):
    return (cam_sw[0] - s) ** 2 + (cam_sw[1] - w) ** 2 > radius * radius


def parked_cars(rng, st: Street, path_sw, cam_sw, span=(-60.0, 90.0)) -> list:
    """Cars in the parking lanes: body, cabin (glass pattern) and dark wheel blocks."""
    rows = []
    for side in (-1, 1):
        k = 0 if side < 0 else 1
        if st.parking[k] <= 0:
            continue
        edge = abs(st.road_edges()[k])
        s = span[0] + rng.uniform(0, 6)
        while s < span[1]:
            length, width = rng.uniform(3.9, 5.0), rng.uniform(1.7, 1.95)
            wc = side * (edge - 0.25 - width / 2)
            sc = s + length / 2
            if rng.random() < 0.8 and _clear(path_sw, sc, wc, length / 2 + 0.9) and \
                    _clear_of_camera(cam_sw, sc, wc, length / 2 + 1.0):
                rows += _car(rng, sc, wc, length, width)
            s += length + rng.uniform(0.8, 7.0)
    return rows


def _car(rng, sc, wc, length, width) -> list:
    colour = (CAR_COLOURS[rng.integers(len(CAR_COLOURS))] * rng.uniform(0.85, 1.1)).tolist()
    body_h = rng.uniform(0.95, 1.15)
    roof = body_h + rng.uniform(0.4, 0.6)
    hl, hw = length / 2, width / 2
    cab0, cab1 = sc - hl * rng.uniform(0.45, 0.6), sc + hl * rng.uniform(0.2, 0.4)
    v = TAG["vehicle"]
    rows = [_box(sc - hl, wc - hw, 0.32, sc + hl, wc + hw, body_h, v, colour, 0, 0.05),
            _box(cab0, wc - hw * 0.9, body_h, cab1, wc + hw * 0.9, roof, v, colour, 2, 0.03)]
    for ds in (-hl * 0.7, hl * 0.7):
        for dw in (-hw * 0.82, hw * 0.82):
            rows.append(_box(sc + ds - 0.33, wc + dw - 0.12, 0.0, sc + ds + 0.33, wc + dw + 0.12,
                             0.62, v, [25, 25, 28], 0, 0.0))
    return rows


def poles_and_trees(rng, st: Street, path_sw, span=(-80.0, 120.0)):
    """Street lamps, sign posts and trees along both sidewalks -> (boxes, cylinders, spheres)."""
    boxes, cyls, spheres = [], [], []
    for side in (-1, 1):
        inner, outer = st.sidewalk_bounds(side)
        w_pole = side * (inner + 0.55)
        s = span[0] + rng.uniform(0, 15)
        while s < span[1]:
            kind = rng.choice(["lamp", "sign", "tree", "none"], p=[0.35, 0.15, 0.35, 0.15])
            w = w_pole if kind != "tree" else side * (inner + min(1.2, (outer - inner) / 2))
            if kind != "none" and _clear(path_sw, s, w, 1.2):
                if kind == "lamp":
                    h = rng.uniform(6.0, 8.5)
                    cyls.append([s, w, CURB, h, 0.09, TAG["pole"], 95, 98, 102, 0.05])
                    a, b = w, w - side * 1.6
                    boxes.append(_box(s - 0.07, min(a, b), h - 0.12, s + 0.07, max(a, b), h,
                                      TAG["pole"], [95, 98, 102]))
                elif kind == "sign":
                    h = rng.uniform(2.3, 3.0)
                    cyls.append([s, w, CURB, h, 0.045, TAG["pole"], 120, 120, 125, 0.0])
                    boxes.append(_box(s - 0.03, w - 0.35, h - 0.7, s + 0.03, w + 0.35, h,
                                      TAG["traffic_sign"], [30, 80, 170] if rng.random() < 0.5
                                      else [200, 30, 30], 0, 0.0))
                else:
                    _tree(rng, s, w, cyls, spheres)
            s += rng.uniform(7, 22)
    return boxes, cyls, spheres


def _tree(rng, s, w, cyls, spheres):
    trunk = rng.uniform(2.0, 3.2)
    cyls.append([s, w, CURB, trunk + 0.5, rng.uniform(0.1, 0.18), TAG["vegetation"],
                 90, 70, 50, 0.25])
    green = np.array([rng.uniform(50, 90), rng.uniform(90, 140), rng.uniform(30, 60)])
    r = rng.uniform(1.2, 2.3)
    for _ in range(int(rng.integers(2, 5))):
        c = np.array([s, w, trunk + r * 0.8]) + rng.normal(0, r * 0.35, 3)
        spheres.append([*c, r * rng.uniform(0.7, 1.0), TAG["vegetation"],
                        *(green * rng.uniform(0.85, 1.15)), 0.45])


def lighting(st: Street) -> np.ndarray:
    """(12,) light table: sun direction (world), ambient, diffuse, zenith, horizon, fog."""
    return np.array([*st.style["sun"], st.style["ambient"], 0.62, 70, 130, 180, 196, 212, 228,
                     450.0])


@dataclass
class SceneTables:
    road: np.ndarray
    bands: np.ndarray
    boxes: np.ndarray
    cylinders: np.ndarray
    spheres: np.ndarray
    light: np.ndarray


def scene_tables(rng, st: Street, path_sw: np.ndarray, cam_sw) -> SceneTables:
    """All primitives of a clip's street, props kept clear of the walker's path."""
    boxes = street_boxes(st) + parked_cars(rng, st, path_sw, cam_sw)
    pb, cyls, spheres = poles_and_trees(rng, st, path_sw)
    boxes += pb
    as2d = lambda rows, n: np.asarray(rows, float).reshape(-1, n)  # noqa: E731
    return SceneTables(st.road_transform(), as2d(ground_bands(st), 10), as2d(boxes, 12),
                       as2d(cyls, 10), as2d(spheres, 9), lighting(st))


# ---------------------------------------------------------------------------------------
# Camera (docs/dataset-format.md, "6. How the recorder placed cameras and walkers")

def look_at_camera(look_at: np.ndarray, lane_heading: float, offset: np.ndarray) -> np.ndarray:
    """Camera transform [x, y, z, pitch, yaw, roll] at look_at + R(lane heading) * offset,
    yawed and pitched towards the look-at point, roll 0."""
    R = rotation_matrix(np.array([0.0, lane_heading, 0.0]))
    pos = np.asarray(look_at, float) + R @ np.asarray(offset, float)
    d = np.asarray(look_at, float) - pos
    n = np.linalg.norm(d)
    yaw = np.degrees(np.arctan2(d[1], d[0]))
    pitch = np.degrees(np.arcsin(np.clip(d[2] / n, -1.0, 1.0))) if n > 0 else 0.0
    return np.array([pos[0], pos[1], pos[2], pitch, yaw, 0.0])
