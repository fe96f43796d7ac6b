"""The 26-joint CARLA pedestrian skeleton and its reference T-poses (docs/dataset-format.md,
"4. The 26-joint skeleton").

Reference poses are loaded from the package data (``resources/carla_skeleton/*.yaml``), which
store locations in centimetres; :func:`reference_pose` returns metres and degrees.
"""
from __future__ import annotations

import functools
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
