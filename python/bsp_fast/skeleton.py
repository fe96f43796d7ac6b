"""The 26-joint CARLA pedestrian skeleton, its reference T-poses (docs/dataset-format.md,
"4. The 26-joint skeleton"), and the joint sets of other pose formats with the maps between
them and the CARLA skeleton (docs/interop.md).

Reference poses are loaded from the package data (``resources/carla_skeleton/*.yaml``), which
store locations in centimetres; :func:`reference_pose` returns metres and degrees.

A :class:`JointSet` is an ordered list of joint names with its left/right pairs (for
flipping) and, where the format defines one, its parents. The sets are ``carla26`` (the
skeleton above), ``coco17`` (COCO keypoints: MMPose, Detectron2), ``body25`` (OpenPose
BODY_25), ``h36m17`` (the 17 Human3.6M joints of VideoPose3D) and ``smpl24`` (the SMPL body
joints of AMASS).

A :class:`SkeletonMap` from one set to another says, for every target joint, where its
value comes from: one source joint (``direct``, copied exactly), the mid-point of two
source joints (``derived``: only the documented standard derivations below, and only with
``derive=True``), or nothing (``missing``). Nothing is ever zero-filled or guessed:
:meth:`SkeletonMap.apply` returns a ``present`` mask beside the points, False for missing
joints and for joints whose source was itself missing. Maps between two non-CARLA sets go
through CARLA-26 (what CARLA lacks, e.g. the COCO ears, is lost).

Standard derivations (``derive=True``, the default):

* COCO-17 -> CARLA ``crl_hips__C`` = mid-point of ``left_hip`` and ``right_hip`` (COCO has
  no pelvis; the same rule gives VideoPose3D's and OpenPose's pelvis/MidHip from COCO);
* COCO-17 -> CARLA ``crl_neck__C`` = mid-point of ``left_shoulder`` and ``right_shoulder``
  (how OpenPose defines its COCO-18 ``Neck``).

The table of which CARLA joints each set fills is :func:`coverage_table` (docs/interop.md).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources

import numpy as np

from ._native import core as _core
from .geometry import forward_kinematics

JOINT_NAMES: tuple = tuple(_core.JOINT_NAMES)
NUM_JOINTS = len(JOINT_NAMES)
PARENTS: tuple = tuple(_core.PARENTS)
ROOT, HIPS, NECK = 0, 1, 8
#: (parent, child) pairs, one per bone.
EDGES: tuple = tuple((p, j) for j, p in enumerate(PARENTS) if p >= 0)
#: Output joint i of a horizontally flipped pose takes input joint FLIP_PERMUTATION[i].
FLIP_PERMUTATION: tuple = tuple(_core.FLIP_PERMUTATION)
JOINT_INDEX = {name: i for i, name in enumerate(JOINT_NAMES)}

#: (age, gender) -> reference skeleton file stem.
MODELS = {
    ("adult", "female"): "sk_female",
    ("adult", "male"): "sk_male",
    ("child", "female"): "sk_girl",
    ("child", "male"): "sk_kid",
}
AGES = ("adult", "child")
GENDERS = ("female", "male")


def _data_file(name: str):
    return resources.files("bsp_fast").joinpath("resources", "carla_skeleton", name)


def _read_yaml(name: str):
    import yaml

    with _data_file(name).open("r", encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def _transforms_array(doc: dict) -> np.ndarray:
    """(26, 6) [x, y, z (m), pitch, yaw, roll (deg)] in skeleton joint order."""
    tr = doc["transforms"]
    missing = [n for n in JOINT_NAMES if n not in tr]
    if missing:
        raise ValueError(f"skeleton file lacks joints {missing}")
    out = np.empty((NUM_JOINTS, 6))
    for i, name in enumerate(JOINT_NAMES):
        loc, rot = tr[name]["location"], tr[name]["rotation"]
        out[i] = [loc["x"] / 100.0, loc["y"] / 100.0, loc["z"] / 100.0,
                  rot["pitch"], rot["yaw"], rot["roll"]]
    return out


def model_name(age: str, gender: str) -> str:
    """Reference skeleton stem for an (age, gender) profile, e.g. ('child','male') -> 'sk_kid'."""
    try:
        return MODELS[(age, gender)]
    except KeyError:
        raise ValueError(f"unknown profile ({age!r}, {gender!r}); allowed ages {AGES}, "
                         f"genders {GENDERS}") from None


@functools.lru_cache(maxsize=None)
def _reference(stem: str, kind: str) -> np.ndarray:
    arr = _transforms_array(_read_yaml(f"{stem}_{kind}.yaml"))
    arr.setflags(write=False)
    return arr


def reference_pose(model: str = "sk_female", kind: str = "relative") -> np.ndarray:
    """Reference T-pose ``(26, 6)`` in metres and degrees (a read-only array).

    ``model`` is a stem (``sk_female``, ``sk_male``, ``sk_girl``, ``sk_kid``) or an
    ``(age, gender)`` tuple. ``kind`` is ``relative`` (each bone relative to its parent)
    or ``absolute`` (component space after FK; shipped for ``sk_female`` only).
    """
    stem = model_name(*model) if isinstance(model, tuple) else model
    if stem not in MODELS.values():
        raise ValueError(f"unknown model {stem!r}; allowed {sorted(MODELS.values())}")
    if kind not in ("relative", "absolute"):
        raise ValueError(f"kind must be 'relative' or 'absolute', got {kind!r}")
    if kind == "absolute" and stem != "sk_female":
        raise ValueError("only sk_female ships an absolute reference pose; "
                         "use forward_kinematics(reference_pose(model)) for the others")
    return _reference(stem, kind)


def structure_parents() -> tuple:
    """Parents derived from ``structure.yaml`` (depth-first order), for consistency checks."""
    names, parents = [], []

    def walk(node, parent):
        for entry in node:
            for name, children in entry.items():
                names.append(name)
                parents.append(parent)
                if children:
                    walk(children, len(names) - 1)

    walk(_read_yaml("structure.yaml")["structure"], -1)
    return tuple(names), tuple(parents)


@functools.lru_cache(maxsize=None)
def _hips_neck(stem: str) -> float:
    joints = forward_kinematics(reference_pose(stem))[:, :3]
    return float(np.linalg.norm(joints[NECK] - joints[HIPS]))


def hips_neck_length(age, gender):
    """Hips-neck distance (metres) of the reference T-pose of an (age, gender) profile,
    from forward kinematics of its reference skeleton: about 0.467 for adults, 0.284 for
    ('child', 'female'), 0.320 for ('child', 'male').

    ``age`` and ``gender`` are strings (-> float) or equally long sequences of strings, e.g.
    a batch's ``meta["age"]`` and ``meta["gender"]`` (-> float64 array). Unknown values
    raise ValueError listing the allowed ones.
    """
    if isinstance(age, str) and isinstance(gender, str):
        return _hips_neck(model_name(age, gender))
    if isinstance(age, str) or isinstance(gender, str) or len(age) != len(gender):
        raise ValueError("age and gender must both be strings or equally long sequences, "
                         f"got {age!r} and {gender!r}")
    return np.array([_hips_neck(model_name(a, g)) for a, g in zip(age, gender)],
                    dtype=np.float64)


# ------------------------------------------------------- other formats' joint sets
@dataclass(frozen=True)
class JointSet:
    """An ordered joint set: ``joints`` (names), ``left``/``right`` (index lists, pair by
    pair), ``parents`` (or None) and a one-line ``description``."""

    name: str
    joints: tuple
    left: tuple
    right: tuple
    parents: tuple | None
    description: str

    def __len__(self) -> int:
        return len(self.joints)

    def index(self, joint: str) -> int:
        try:
            return self.joints.index(joint)
        except ValueError:
            raise ValueError(f"{self.name} has no joint {joint!r}; its joints: "
                             f"{list(self.joints)}") from None

    @property
    def flip_permutation(self) -> tuple:
        """Output joint ``i`` of a mirrored pose takes input joint ``flip_permutation[i]``."""
        perm = list(range(len(self.joints)))
        for a, b in zip(self.left, self.right):
            perm[a], perm[b] = b, a
        return tuple(perm)


def _pairs(names, right_of) -> tuple:
    """Left and right index lists of the joints whose names differ by a side marker."""
    left, right = [], []
    for i, n in enumerate(names):
        other = right_of(n)
        if other is not None and other in names:
            left.append(i)
            right.append(names.index(other))
    return tuple(left), tuple(right)


def _carla_set() -> JointSet:
    names = tuple(JOINT_NAMES)
    left, right = _pairs(names, lambda n: n[:-3] + "__R" if n.endswith("__L") else None)
    return JointSet("carla26", names, left, right, tuple(PARENTS),
                    "CARLA pedestrian skeleton (CARLA-BSP, this package)")


_COCO = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
         "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip",
         "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
# OpenPose doc/02_output.md, "Pose Output Format (BODY_25)"
_BODY25 = ("Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
           "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye",
           "REar", "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel")
_BODY25_PARENTS = (1, -1, 1, 2, 3, 1, 5, 6, 1, 8, 9, 10, 8, 12, 13, 0, 0, 15, 16, 14, 19, 14,
                   11, 22, 11)
# VideoPose3D (common/h36m_dataset.py): Human3.6M's 32 joints less the static ones
# [4, 5, 9, 10, 11, 16, 20, 21, 22, 23, 24, 28, 29, 30, 31], shoulders re-parented to the
# thorax; names as in Martinez et al.'s H36M_NAMES.
_H36M = ("pelvis", "right_hip", "right_knee", "right_foot", "left_hip", "left_knee",
         "left_foot", "spine", "thorax", "neck_nose", "head", "left_shoulder", "left_elbow",
         "left_wrist", "right_shoulder", "right_elbow", "right_wrist")
_H36M_PARENTS = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)
# SMPL body joints (the first 24 of SMPL-H / SMPL-X: AMASS)
_SMPL = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
         "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
         "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
         "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand")
_SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19,
                 20, 21)


def _word_side(n):
    return "right_" + n[5:] if n.startswith("left_") else None


def _letter_side(n):
    return "R" + n[1:] if n.startswith("L") and n[1:2].isupper() else None


def _make_sets() -> dict:
    sets = [_carla_set()]
    for name, joints, side, parents, what in (
            ("coco17", _COCO, _word_side, None, "COCO keypoints (MMPose, Detectron2)"),
            ("body25", _BODY25, _letter_side, _BODY25_PARENTS, "OpenPose BODY_25"),
            ("h36m17", _H36M, _word_side, _H36M_PARENTS, "Human3.6M, 17 joints (VideoPose3D)"),
            ("smpl24", _SMPL, _word_side, _SMPL_PARENTS, "SMPL body joints (AMASS)")):
        left, right = _pairs(joints, side)
        sets.append(JointSet(name, joints, left, right, parents, what))
    return {s.name: s for s in sets}


JOINT_SETS: dict = _make_sets()
CARLA: JointSet = JOINT_SETS["carla26"]


def _sided(pairs: dict) -> dict:
    """Expands ``{"left_x": "crl_y__L"}`` entries to both sides."""
    out = {}
    for src, dst in pairs.items():
        out[src] = dst
        if src.startswith("left_"):
            out["right_" + src[5:]] = dst[:-3] + "__R"
        elif src[:1] == "L" and src[1:2].isupper():
            out["R" + src[1:]] = dst[:-3] + "__R"
    return out


# source joint -> CARLA joint, copied exactly (facts: the formats' documentation)
_TO_CARLA = {
    "coco17": _sided({"nose": "crl_Head__C", "left_eye": "crl_eye__L",
                      "left_shoulder": "crl_arm__L", "left_elbow": "crl_foreArm__L",
                      "left_wrist": "crl_hand__L", "left_hip": "crl_thigh__L",
                      "left_knee": "crl_leg__L", "left_ankle": "crl_foot__L"}),
    "body25": _sided({"MidHip": "crl_hips__C", "Neck": "crl_neck__C", "Nose": "crl_Head__C",
                      "LShoulder": "crl_arm__L", "LElbow": "crl_foreArm__L",
                      "LWrist": "crl_hand__L", "LEye": "crl_eye__L", "LHip": "crl_thigh__L",
                      "LKnee": "crl_leg__L", "LAnkle": "crl_foot__L", "LBigToe": "crl_toe__L",
                      "LSmallToe": "crl_toeEnd__L"}),
    "h36m17": _sided({"pelvis": "crl_hips__C", "left_hip": "crl_thigh__L",
                      "left_knee": "crl_leg__L", "left_foot": "crl_foot__L",
                      "thorax": "crl_neck__C", "neck_nose": "crl_Head__C",
                      "left_shoulder": "crl_arm__L", "left_elbow": "crl_foreArm__L",
                      "left_wrist": "crl_hand__L"}),
    "smpl24": _sided({"pelvis": "crl_hips__C", "spine1": "crl_spine__C",
                      "spine3": "crl_spine01__C", "left_collar": "crl_shoulder__L",
                      "left_shoulder": "crl_arm__L", "left_elbow": "crl_foreArm__L",
                      "left_wrist": "crl_hand__L", "neck": "crl_neck__C", "head": "crl_Head__C",
                      "left_hip": "crl_thigh__L", "left_knee": "crl_leg__L",
                      "left_ankle": "crl_foot__L", "left_foot": "crl_toe__L"}),
}
# CARLA joint -> the two source joints whose mid-point it is (the standard derivations)
_DERIVED = {
    "coco17": {"crl_hips__C": ("left_hip", "right_hip"),
               "crl_neck__C": ("left_shoulder", "right_shoulder")},
}
_ALIASES = {"carla": "carla26", "coco": "coco17", "openpose": "body25", "body_25": "body25",
            "h36m": "h36m17", "smpl": "smpl24", "amass": "smpl24"}


def joint_set(name) -> JointSet:
    """A joint set by name (``carla26``, ``coco17``, ``body25``, ``h36m17``, ``smpl24``; also
    ``carla``, ``coco``, ``openpose``, ``h36m``, ``smpl``, ``amass``) or a JointSet as is."""
    if isinstance(name, JointSet):
        return name
    key = _ALIASES.get(str(name).lower(), str(name).lower())
    if key not in JOINT_SETS:
        raise ValueError(f"unknown joint set {name!r}; allowed: {', '.join(JOINT_SETS)} "
                         f"(aliases {', '.join(_ALIASES)})")
    return JOINT_SETS[key]


@dataclass(frozen=True)
class SkeletonMap:
    """Where each ``target`` joint comes from in ``source``: ``sources[i]`` is ``()``
    (missing), ``(j,)`` (copied from source joint j) or ``(a, b)`` (mid-point)."""

    source: JointSet
    target: JointSet
    sources: tuple

    @property
    def present(self) -> np.ndarray:
        """``(J_target,)`` bool: True where the map fills the joint."""
        return np.array([len(s) > 0 for s in self.sources])

    @property
    def kinds(self) -> tuple:
        """``direct``, ``derived`` or ``missing`` per target joint."""
        return tuple({0: "missing", 1: "direct"}.get(len(s), "derived") for s in self.sources)

    def describe(self) -> list:
        """``(target joint, kind, source joint names)`` rows."""
        return [(self.target.joints[i], k, tuple(self.source.joints[j] for j in s))
                for i, (k, s) in enumerate(zip(self.kinds, self.sources))]

    def apply(self, points, present=None, fill: float = np.nan):
        """Maps ``(..., J_source, D)`` points (any D: 2D, 3D, with a score column ...) to
        ``(..., J_target, D)``; returns ``(points, present)``. Direct joints are copied
        bit for bit, derived ones are ``(a + b) / 2`` (computed in float64); a target joint is present when the
        map fills it and all its sources are present (``present``: ``(..., J_source)``
        bool, default all). Missing joints hold ``fill`` (NaN by default)."""
        p = np.asarray(points)
        if p.ndim < 2 or p.shape[-2] != len(self.source):
            raise ValueError(f"points must be (..., {len(self.source)}, D) for "
                             f"{self.source.name}, got shape {p.shape}")
        src_ok = (np.ones(p.shape[:-1], bool) if present is None
                  else np.broadcast_to(np.asarray(present, bool), p.shape[:-1]))
        dtype = p.dtype if np.issubdtype(p.dtype, np.floating) else np.float64
        out = np.full(p.shape[:-2] + (len(self.target), p.shape[-1]), fill, dtype)
        ok = np.zeros(p.shape[:-2] + (len(self.target),), bool)
        for i, s in enumerate(self.sources):
            if len(s) == 1:
                out[..., i, :] = p[..., s[0], :]
                ok[..., i] = src_ok[..., s[0]]
            elif len(s) == 2:
                # in float64 whatever the input, so float32 and float64 copies of the
                # same points give the same float32 mid-point
                out[..., i, :] = (p[..., s[0], :].astype(np.float64) + p[..., s[1], :]) / 2
                ok[..., i] = src_ok[..., s[0]] & src_ok[..., s[1]]
        out[~ok] = fill
        return out, ok


def _to_carla(src: JointSet, derive: bool) -> tuple:
    direct = {CARLA.index(c): src.index(s) for s, c in _TO_CARLA[src.name].items()}
    rows = [(direct[i],) if i in direct else () for i in range(len(CARLA))]
    if derive:
        for c, (a, b) in _DERIVED.get(src.name, {}).items():
            rows[CARLA.index(c)] = (src.index(a), src.index(b))
    return tuple(rows)


def _from_carla(dst: JointSet) -> tuple:
    inverse = {s: CARLA.index(c) for s, c in _TO_CARLA[dst.name].items()}
    return tuple((inverse[n],) if n in inverse else () for n in dst.joints)


def skeleton_map(source, target, derive: bool = True) -> SkeletonMap:
    """The map from joint set ``source`` to ``target`` (names or JointSets). ``derive``
    allows the standard mid-point derivations (module docstring); without it those
    joints are missing."""
    src, dst = joint_set(source), joint_set(target)
    if not isinstance(derive, bool):
        raise ValueError(f"derive must be True or False, got {derive!r}")
    if src.name == dst.name:
        return SkeletonMap(src, dst, tuple((i,) for i in range(len(src))))
    if dst.name == "carla26":
        return SkeletonMap(src, dst, _to_carla(src, derive))
    if src.name == "carla26":
        return SkeletonMap(src, dst, _from_carla(dst))
    first = _to_carla(src, derive)  # through CARLA-26
    rows = tuple(first[c[0]] if c else () for c in _from_carla(dst))
    return SkeletonMap(src, dst, rows)


def coverage_table(derive: bool = True) -> str:
    """Markdown table: for each CARLA joint, the joint of each set that fills it
    (``mid(a, b)`` for derivations, ``-`` when missing)."""
    others = [s for s in JOINT_SETS if s != "carla26"]
    maps = {s: skeleton_map(s, "carla26", derive) for s in others}
    lines = ["| CARLA joint | " + " | ".join(others) + " |",
             "|---|" + "---|" * len(others)]
    for i, name in enumerate(CARLA.joints):
        cells = []
        for s in others:
            src = [JOINT_SETS[s].joints[j] for j in maps[s].sources[i]]
            cells.append("-" if not src else src[0] if len(src) == 1
                         else f"mid({src[0]}, {src[1]})")
        lines.append(f"| {i} `{name}` | " + " | ".join(cells) + " |")
    counts = [f"{int(maps[s].present.sum())}" for s in others]
    lines.append("| **joints filled** | " + " | ".join(counts) + " |")
    return "\n".join(lines)
