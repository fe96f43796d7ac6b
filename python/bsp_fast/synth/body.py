"""The pedestrian's volumetric body: shaded capsules along the bones plus a head and hair,
sized by the model (hips-neck distance), clothed with per-clip colours."""
from __future__ import annotations

import numpy as np

from .. import skeleton as sk

J = sk.JOINT_INDEX
# hips-neck distance of the adult models (docs/dataset-format.md, "4. The 26-joint skeleton")
ADULT_TORSO = 0.467

SKIN = np.array([[255, 219, 172], [241, 194, 125], [224, 172, 105], [198, 134, 66],
                 [141, 85, 36], [92, 56, 30]], float)
HAIR = np.array([[30, 22, 18], [70, 45, 25], [120, 80, 40], [200, 170, 100], [90, 90, 90],
                 [15, 15, 15]], float)
TROUSERS = np.array([[40, 60, 100], [30, 30, 32], [150, 130, 90], [100, 100, 105],
                     [70, 50, 40], [60, 80, 60]], float)
SHOES = np.array([[20, 20, 20], [230, 230, 230], [90, 60, 40], [40, 40, 60]], float)

# (name, colour slot); capsule geometry in body_capsules follows this order.
PARTS = ("pelvis", "trousers"), ("torso", "shirt"), ("shoulders", "shirt"), \
    ("flank_L", "shirt"), ("flank_R", "shirt"), ("neck", "skin"), ("head", "skin"), \
    ("hair", "hair"), ("upper_arm_L", "shirt"), ("upper_arm_R", "shirt"), \
    ("forearm_L", "sleeve"), ("forearm_R", "sleeve"), ("hand_L", "skin"), \
    ("hand_R", "skin"), ("thigh_L", "trousers"), ("thigh_R", "trousers"), \
    ("shin_L", "shin"), ("shin_R", "shin"), ("foot_L", "shoes"), ("foot_R", "shoes"), \
    ("toes_L", "shoes"), ("toes_R", "shoes")


def sample_colours(rng: np.random.Generator) -> np.ndarray:
    """(len(PARTS), 3) RGB 0..255 for one pedestrian."""
    hsv_h = rng.uniform(0, 1)
    sat, val = rng.uniform(0.2, 0.9), rng.uniform(0.35, 0.95)
    shirt = _hsv(hsv_h, sat, val)
    slots = {
        "skin": SKIN[rng.integers(len(SKIN))] * rng.uniform(0.95, 1.05),
        "hair": HAIR[rng.integers(len(HAIR))],
        "shirt": shirt,
        "trousers": TROUSERS[rng.integers(len(TROUSERS))] * rng.uniform(0.85, 1.15),
        "shoes": SHOES[rng.integers(len(SHOES))],
    }
    slots["sleeve"] = slots["skin"] if rng.random() < 0.4 else shirt
    slots["shin"] = slots["skin"] if rng.random() < 0.25 else slots["trousers"]
    return np.clip(np.array([slots[slot] for _, slot in PARTS]), 0, 255)


def _hsv(h, s, v) -> np.ndarray:
    i = int(h * 6) % 6
    f = h * 6 - int(h * 6)
    p, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    rgb = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)][i]
    return np.array(rgb) * 255.0


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def body_capsules(world_xyz: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Capsules (frames, len(PARTS), 7) [ax, ay, az, bx, by, bz, radius] from world joint
    positions (frames, 26, 3) and the walker's forward unit vectors (frames, 3)."""
    P = np.asarray(world_xyz, float)
    g = lambda name: P[:, J[name]]  # noqa: E731
    s = np.linalg.norm(g("crl_neck__C") - g("crl_hips__C"), axis=-1)[:, None] / ADULT_TORSO
    r = s ** 0.85  # children are a bit stockier than scaled-down adults
    up = np.array([0.0, 0.0, 1.0])
    hips, neck, head, sp1 = g("crl_hips__C"), g("crl_neck__C"), g("crl_Head__C"), \
        g("crl_spine01__C")
    axis = _unit(head - neck)
    head_r = 0.092 * s ** 0.6
    head_a, head_b = head + axis * 0.035 * s, head + axis * 0.085 * s
    caps = [(g("crl_thigh__L"), g("crl_thigh__R"), 0.10 * r),
            (hips, 0.5 * (sp1 + neck), 0.125 * r),
            (0.8 * g("crl_arm__L") + 0.2 * neck, 0.8 * g("crl_arm__R") + 0.2 * neck, 0.08 * r)]
    for side in ("L", "R"):
        low = 0.5 * (hips + g(f"crl_thigh__{side}")) + up * 0.12 * s
        high = 0.75 * g(f"crl_arm__{side}") + 0.25 * sp1 - up * 0.08 * s
        caps.append((low, high, 0.095 * r))
    caps += [(neck, head, 0.05 * r), (head_a, head_b, head_r),
             (head_a - forward * 0.022 * s + axis * 0.01 * s,
              head_b - forward * 0.022 * s + axis * 0.01 * s, head_r * 1.02)]
    limb = [("crl_arm__{}", "crl_foreArm__{}", 0.048), ("crl_foreArm__{}", "crl_hand__{}", 0.04)]
    for a, b, rad in limb:
        for side in ("L", "R"):
            caps.append((g(a.format(side)), g(b.format(side)), rad * r))
    for side in ("L", "R"):
        wrist, elbow = g(f"crl_hand__{side}"), g(f"crl_foreArm__{side}")
        caps.append((wrist, wrist + _unit(wrist - elbow) * 0.08 * s, 0.036 * r))
    limb = [("crl_thigh__{}", "crl_leg__{}", 0.075), ("crl_leg__{}", "crl_foot__{}", 0.055),
            ("crl_foot__{}", "crl_toe__{}", 0.045), ("crl_toe__{}", "crl_toeEnd__{}", 0.035)]
    for a, b, rad in limb:
        for side in ("L", "R"):
            caps.append((g(a.format(side)), g(b.format(side)), rad * r))
    out = np.empty((P.shape[0], len(caps), 7))
    for k, (a, b, rad) in enumerate(caps):
        out[:, k, :3], out[:, k, 3:6] = a, b
        out[:, k, 6] = np.broadcast_to(rad, (P.shape[0], 1))[:, 0]
    return out
