"""``--motion FILE``: drive the body with a BVH / FBX / glTF animation instead of the gait.

The file is read by assimp in the C++ core (bsp_fast._core.load_motion), resampled at the
clip rate and retargeted onto the CARLA skeleton:

1. Source joints are matched to CARLA joints by name (:data:`JOINT_MAP`, after
   normalisation: namespace prefixes such as ``mixamorig:`` and ``Bip01`` dropped, lower
   case, side tokens ``L`` / ``Right`` / ``_l`` turned into a ``left`` / ``right`` prefix,
   separators removed). Hips (else the thighs' nearest common ancestor), both thighs, legs
   (knees) and feet are required.
2. Source axes are taken as Y up with the character facing +Z (BVH, glTF and Mixamo FBX
   convention; its left is +X). They map onto the CARLA mesh axes (x left, y forward,
   z up). Units do not matter: only directions are used.
3. Root translation is dropped (the walker's path moves the body) and the facing direction,
   smoothed over one second, is removed so the body faces its walking direction.
4. The hips get the rotation of the source pelvis frame (left-right hip axis, hips->chest
   axis) relative to the file's rest pose; every other mapped bone is swung (minimal
   rotation) so its direction to its mapped child matches the source bone; unmapped bones
   follow their parent. Feet are then grounded as for the gait.

Clip frame i uses source frame (offset + i) mod n: short animations loop.
"""
from __future__ import annotations

import functools
import hashlib
import re

import numpy as np

from .. import skeleton as sk
from .._native import core as _core
from . import gait

J = sk.JOINT_INDEX

_SIDED = {
    "shoulder": ["{s}shoulder", "{s}collar", "{s}clavicle"],
    "arm": ["{s}arm", "{s}upperarm", "{s}shldr", "{s}humerus"],
    "foreArm": ["{s}forearm", "{s}lowerarm", "{s}elbow", "{s}radius"],
    "hand": ["{s}hand", "{s}wrist"],
    "thigh": ["{s}upleg", "{s}thigh", "{s}upperleg", "{s}femur", "{s}hip"],
    "leg": ["{s}leg", "{s}lowerleg", "{s}shin", "{s}knee", "{s}calf", "{s}tibia"],
    "foot": ["{s}foot", "{s}ankle"],
    "toe": ["{s}toebase", "{s}toe", "{s}toes", "{s}ball"],
}

#: CARLA joint -> normalised source names, in order of preference.
JOINT_MAP: dict = {
    "crl_hips__C": ["hips", "pelvis", "hip"],
    "crl_spine__C": ["spine", "lowerback", "abdomen", "spine0"],
    "crl_spine01__C": ["spine2", "chest", "upperchest", "spine1", "upperback", "spine3"],
    "crl_neck__C": ["neck", "neck1", "lowerneck"],
    "crl_Head__C": ["head"],
}
for _bone, _names in _SIDED.items():
    for _side, _full in (("L", "left"), ("R", "right")):
        JOINT_MAP[f"crl_{_bone}__{_side}"] = [n.format(s=_full) for n in _names]

_SIDED_NAMES = {n for names in JOINT_MAP.values() for n in names if n.startswith("left")}

REQUIRED = ("crl_hips__C", "crl_thigh__L", "crl_thigh__R", "crl_leg__L", "crl_leg__R",
            "crl_foot__L", "crl_foot__R")

# Bones aimed at their child: (joint, child) in CARLA index order.
AIMED = [("crl_spine__C", "crl_spine01__C"), ("crl_spine01__C", "crl_neck__C"),
         ("crl_neck__C", "crl_Head__C")]
for _side in ("L", "R"):
    AIMED += [(f"crl_shoulder__{_side}", f"crl_arm__{_side}"),
              (f"crl_arm__{_side}", f"crl_foreArm__{_side}"),
              (f"crl_foreArm__{_side}", f"crl_hand__{_side}"),
              (f"crl_thigh__{_side}", f"crl_leg__{_side}"),
              (f"crl_leg__{_side}", f"crl_foot__{_side}"),
              (f"crl_foot__{_side}", f"crl_toe__{_side}")]

# Source (Y up, facing +Z, left +X) -> CARLA mesh (x left, y forward, z up).
SOURCE_TO_MESH = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])


def normalise_name(name: str) -> str:
    """'mixamorig:LeftUpLeg' -> 'leftupleg', 'upperarm_L' -> 'leftupperarm',
    'Bip01 L Thigh' -> 'leftthigh', 'LHip' -> 'lefthip'."""
    n = re.split(r"[:|]", name)[-1].lower()
    tokens = [t for t in re.split(r"[_.\- ]+", n)
              if t and t != "def" and not re.fullmatch(r"bip0*1", t)]  # Rigify, 3ds Max
    side = ""
    for t in tokens:
        if t in ("l", "left", "r", "right"):
            side = "left" if t[0] == "l" else "right"
    n = side + "".join(t for t in tokens if t not in ("l", "left", "r", "right"))
    if n[:1] in ("l", "r") and ("left" + n[1:]) in _SIDED_NAMES:  # LHip, rShldr, RFoot
        n = ("left" if n[0] == "l" else "right") + n[1:]
    return n


def _ancestors(j: int, parents) -> list:
    out = []
    while j >= 0:
        out.append(j)
        j = parents[j]
    return out


def match_joints(names, parents=None) -> dict:
    """CARLA joint name -> source node index for every joint that has a match. Without a
    hips match, the nearest common ancestor of the two thighs stands for the hips."""
    index = {}
    for i, name in enumerate(names):
        index.setdefault(normalise_name(name), i)
    out = {}
    for carla, candidates in JOINT_MAP.items():
        for c in candidates:
            if c in index:
                out[carla] = index[c]
                break
    if "crl_hips__C" not in out and parents is not None and \
            "crl_thigh__L" in out and "crl_thigh__R" in out:
        left = _ancestors(parents[out["crl_thigh__L"]], parents)
        right = set(_ancestors(parents[out["crl_thigh__R"]], parents))
        common = [j for j in left if j in right]
        if common:
            out["crl_hips__C"] = common[0]
    return out


def _globals(local: np.ndarray, parents) -> np.ndarray:
    G = np.empty_like(local)
    for j, p in enumerate(parents):
        G[..., j, :, :] = local[..., j, :, :] if p < 0 else G[..., p, :, :] @ local[..., j, :, :]
    return G


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) smallest rotations taking unit vectors a to unit vectors b."""
    a, b = np.broadcast_arrays(_unit(a), _unit(b))
    k = np.cross(a, b)
    c = np.sum(a * b, -1)
    s2 = np.sum(k * k, -1)
    K = np.zeros(a.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    f = np.where(s2 > 1e-15, (1 - c) / np.where(s2 > 1e-15, s2, 1.0), 0.5)
    R = np.eye(3) + K + (K @ K) * f[..., None, None]
    opposite = (s2 <= 1e-15) & (c < 0)
    if np.any(opposite):  # half turn about any axis perpendicular to a
        ax = _unit(np.cross(a[opposite], np.where(np.abs(a[opposite][:, :1]) < 0.9,
                                                  [1.0, 0, 0], [0, 1.0, 0])))
        R[opposite] = 2 * ax[:, :, None] * ax[:, None, :] - np.eye(3)
    return R


def _pelvis_frame(P, m) -> np.ndarray:
    """Columns (left, forward, up) of the pelvis from mesh-axis positions (..., N, 3)."""
    left = P[..., m["crl_thigh__L"], :] - P[..., m["crl_thigh__R"], :]
    top = next((m[k] for k in ("crl_spine01__C", "crl_neck__C", "crl_spine__C") if k in m),
               None)
    up = _unit(P[..., top, :] - P[..., m["crl_hips__C"], :]) if top is not None else \
        np.broadcast_to([0.0, 0.0, 1.0], left.shape)
    x = _unit(left - np.sum(left * up, -1, keepdims=True) * up)
    return np.stack([x, np.cross(up, x), up], -1)


def _face_forward(P, m, fps) -> np.ndarray:
    """Removes root translation and the (smoothed) facing direction from positions."""
    P = P - P[..., m["crl_hips__C"]:m["crl_hips__C"] + 1, :]
    left = P[:, m["crl_thigh__L"]] - P[:, m["crl_thigh__R"]]
    psi = np.unwrap(np.arctan2(left[:, 1], left[:, 0]))
    w = max(1, int(round(fps)))
    if len(psi) > 1:
        pad = np.pad(psi, (w // 2, w - 1 - w // 2), mode="edge")
        psi = np.convolve(pad, np.ones(w) / w, mode="valid")
    R = gait.rz(-np.degrees(psi))
    return np.einsum("fij,fnj->fni", R, P)


class Motion:
    """A loaded animation, retargetable onto any of the four CARLA models."""

    def __init__(self, path: str, fps: float = 30.0):
        data = _core.load_motion(str(path), float(fps), 0)
        self.path, self.fps = str(path), float(fps)
        self.names = list(data["names"])
        parents = [int(p) for p in data["parents"]]
        self.mapping = match_joints(self.names, parents)
        missing = [j for j in REQUIRED if j not in self.mapping]
        if missing:
            raise _core.MotionError(
                f"cannot retarget motion '{path}': no source joint for {missing}; joint names "
                f"in the file: {self.names}; accepted names are listed in "
                "bsp_fast.synth.motion.JOINT_MAP")
        to_mesh = lambda G: G[..., :3, 3] @ SOURCE_TO_MESH.T  # noqa: E731
        self.positions = _face_forward(to_mesh(_globals(data["local"], parents)), self.mapping,
                                       fps)
        self.rest = _face_forward(to_mesh(_globals(data["rest"][None], parents)),
                                  self.mapping, fps)[0]
        self.frames = self.positions.shape[0]
        with open(path, "rb") as fh:
            self.sha256 = hashlib.sha256(fh.read()).hexdigest()

    @functools.lru_cache(maxsize=4)
    def deltas(self, stem: str) -> np.ndarray:
        """Global body-axis deltas (n, 26, 3, 3) of every source frame for a CARLA model."""
        m, P = self.mapping, self.positions
        _, comp0, _ = gait.reference(stem)
        D = np.broadcast_to(np.eye(3), (self.frames, 26, 3, 3)).copy()
        D[:, J["crl_hips__C"]] = _pelvis_frame(P, m) @ _pelvis_frame(self.rest, m).T
        aimed = {J[a]: J[b] for a, b in AIMED}
        for j in range(2, 26):
            D[:, j] = D[:, sk.PARENTS[j]]
            c = aimed.get(j)
            name, child = sk.JOINT_NAMES[j], sk.JOINT_NAMES[c] if c is not None else None
            if c is None or name not in m or child not in m:
                continue
            v = D[:, j] @ _unit(comp0[c, :3] - comp0[j, :3])
            u = P[:, m[child]] - P[:, m[name]]
            D[:, j] = min_rotation(v, u) @ D[:, j]
        return D

    def relative_poses(self, stem: str, frames: int, fps: float, phase: float = 0.0,
                       scale: float = 1.0):
        """Relative poses (frames, 26, 6) looping the animation from a phase in [0, 2 pi)
        (``scale``: bone lengths relative to the reference skeleton's)."""
        if abs(fps - self.fps) > 1e-9:
            raise ValueError(f"motion sampled at {self.fps} fps, clip runs at {fps}")
        offset = int(phase / (2 * np.pi) * self.frames) % self.frames
        idx = (offset + np.arange(frames)) % self.frames
        return gait.pose_from_deltas(stem, self.deltas(stem)[idx], scale)


@functools.lru_cache(maxsize=2)
def load(path: str, fps: float = 30.0) -> Motion:
    """Cached per process (workers load the file once)."""
    return Motion(path, fps)
