"""Joint sets and skeleton maps (bsp_fast.skeleton) against the formats' published facts."""
from pathlib import Path

import numpy as np
import pytest

from bsp_fast import skeleton as S

REPO = Path(__file__).resolve().parents[2]
COCO = ["nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
        "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip",
        "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle"]


def test_sets_sizes_orders_and_sides():
    sizes = {n: len(s) for n, s in S.JOINT_SETS.items()}
    assert sizes == {"carla26": 26, "coco17": 17, "body25": 25, "h36m17": 17, "smpl24": 24}
    assert list(S.JOINT_SETS["coco17"].joints) == COCO
    assert S.CARLA.joints == S.JOINT_NAMES
    b = S.JOINT_SETS["body25"].joints  # OpenPose's documented indices
    assert (b[0], b[1], b[8], b[15], b[18], b[19], b[21], b[22], b[24]) == (
        "Nose", "Neck", "MidHip", "REye", "LEar", "LBigToe", "LHeel", "RBigToe", "RHeel")
    # VideoPose3D's keypoints_symmetry for its coco and h36m layouts
    coco, h36m = S.JOINT_SETS["coco17"], S.JOINT_SETS["h36m17"]
    assert (list(coco.left), list(coco.right)) == ([1, 3, 5, 7, 9, 11, 13, 15],
                                                   [2, 4, 6, 8, 10, 12, 14, 16])
    assert (list(h36m.left), list(h36m.right)) == ([4, 5, 6, 11, 12, 13], [1, 2, 3, 14, 15, 16])
    assert h36m.parents == (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)
    assert S.CARLA.flip_permutation == tuple(S.FLIP_PERMUTATION)
    for s in S.JOINT_SETS.values():
        perm = np.array(s.flip_permutation)
        assert np.array_equal(perm[perm], np.arange(len(s)))  # an involution
        assert len(s.left) == len(s.right)
        if s.parents is not None:
            assert len(s.parents) == len(s) and s.parents.count(-1) == 1


def test_body25_and_smpl_fill_the_21_documented_carla_joints():
    missing = {name: {S.CARLA.joints[i] for i, p in enumerate(S.skeleton_map(name, "carla").present)
                      if not p} for name in ("body25", "smpl24")}
    assert missing["body25"] == {"crl_root", "crl_spine__C", "crl_spine01__C",
                                 "crl_shoulder__L", "crl_shoulder__R"}
    assert missing["smpl24"] == {"crl_root", "crl_eye__L", "crl_eye__R", "crl_toeEnd__L",
                                 "crl_toeEnd__R"}
    m = dict((t, src) for t, _, src in S.skeleton_map("smpl", "carla").describe())
    assert m["crl_shoulder__L"] == ("left_collar",) and m["crl_toe__R"] == ("right_foot",)
    assert m["crl_spine__C"] == ("spine1",) and m["crl_spine01__C"] == ("spine3",)


def test_carla_coco_carla_round_trip_keeps_mapped_joints_exactly():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1000, (4, 5, 26, 2)).astype(np.float32)
    coco, ok = S.skeleton_map("carla26", "coco17").apply(pts)
    assert ok.shape == (4, 5, 17)
    assert not ok[..., 3].any() and not ok[..., 4].any()  # ears: CARLA has none
    assert np.isnan(coco[..., 3:5, :]).all()
    back, ok2 = S.skeleton_map("coco17", "carla26").apply(coco, ok)
    kinds = S.skeleton_map("coco17", "carla26").kinds
    direct = [i for i, k in enumerate(kinds) if k == "direct"]
    assert len(direct) == 15
    assert np.array_equal(back[..., direct, :], pts[..., direct, :])  # bit for bit
    assert ok2[..., direct].all()
    J = S.JOINT_INDEX
    mid = (pts[..., J["crl_thigh__L"], :].astype(np.float64) + pts[..., J["crl_thigh__R"], :]) / 2
    assert np.array_equal(back[..., J["crl_hips__C"], :], mid.astype(np.float32))
    neck = (pts[..., J["crl_arm__L"], :].astype(np.float64) + pts[..., J["crl_arm__R"], :]) / 2
    assert np.array_equal(back[..., J["crl_neck__C"], :], neck.astype(np.float32))
    rest = [i for i, k in enumerate(kinds) if k == "missing"]
    assert {S.JOINT_NAMES[i] for i in rest} == {
        "crl_root", "crl_spine__C", "crl_spine01__C", "crl_shoulder__L", "crl_shoulder__R",
        "crl_toe__R", "crl_toeEnd__R", "crl_toe__L", "crl_toeEnd__L"}
    assert not ok2[..., rest].any() and np.isnan(back[..., rest, :]).all()
    # without derivations hips and neck are missing too
    plain, ok3 = S.skeleton_map("coco17", "carla26", derive=False).apply(coco, ok)
    assert not ok3[..., J["crl_hips__C"]].any() and not ok3[..., J["crl_neck__C"]].any()


def test_missing_sources_make_missing_targets():
    coco = np.arange(17 * 2, dtype=np.float64).reshape(17, 2) + 1
    present = np.ones(17, bool)
    present[11] = False  # left_hip
    out, ok = S.skeleton_map("coco", "carla").apply(coco, present, fill=0.0)
    J = S.JOINT_INDEX
    assert not ok[J["crl_thigh__L"]] and not ok[J["crl_hips__C"]]  # derived needs both
    assert ok[J["crl_thigh__R"]] and ok[J["crl_neck__C"]]
    assert np.array_equal(out[J["crl_thigh__L"]], [0.0, 0.0])


@pytest.mark.parametrize("name", ["coco17", "body25", "h36m17", "smpl24"])
def test_maps_respect_left_and_right(name):
    # mirroring then mapping = mapping then mirroring, both ways: no side is swapped
    rng = np.random.default_rng(1)
    for src, dst in (("carla26", name), (name, "carla26")):
        m = S.skeleton_map(src, dst)
        p = rng.normal(size=(3, len(m.source), 2))
        a, oka = m.apply(p[:, list(m.source.flip_permutation)])
        b, okb = m.apply(p)
        b, okb = b[:, list(m.target.flip_permutation)], okb[:, list(m.target.flip_permutation)]
        assert np.array_equal(oka, okb)
        assert np.array_equal(a[oka], b[okb])


def test_maps_between_other_sets_go_through_carla():
    m = S.skeleton_map("coco17", "h36m17")
    d = {t: (k, src) for t, k, src in m.describe()}
    assert d["pelvis"] == ("derived", ("left_hip", "right_hip"))
    assert d["thorax"] == ("derived", ("left_shoulder", "right_shoulder"))
    assert d["right_foot"] == ("direct", ("right_ankle",))
    assert d["spine"] == ("missing", ()) and d["head"] == ("missing", ())


def test_bad_names_and_shapes():
    with pytest.raises(ValueError, match="unknown joint set 'mpii'.*coco17"):
        S.joint_set("mpii")
    with pytest.raises(ValueError, match=r"\(\.\.\., 17, D\)"):
        S.skeleton_map("coco", "carla").apply(np.zeros((3, 26, 2)))
    with pytest.raises(ValueError, match="derive"):
        S.skeleton_map("coco", "carla", derive="yes")


def test_docs_table_is_the_code_table():
    doc = (REPO / "docs" / "interop.md").read_text(encoding="utf-8")
    assert S.coverage_table() in doc
