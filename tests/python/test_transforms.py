"""Transforms of docs/dataset-format.md, "8. What the loaders compute" on hand-made poses."""
import numpy as np
import pytest

from bsp_fast.data import (
    Compose,
    Deform,
    GaussianNoise,
    HipsNeckDenormalize,
    HipsNeckNormalize,
    HorizontalFlip,
    MissingJoints,
    RandomFlipRotate,
    RandomRotation,
    denormalize_hips_neck,
    flip_horizontal,
    flip_rotate,
    joint_bbox,
    normalize_hips_neck,
    normalize_hips_neck_3d,
    rotate,
)
from bsp_fast.skeleton import FLIP_PERMUTATION, HIPS, NECK

J = 26


def hand_pose():
    """Joints spread over a 40 x 100 px box; hips (100, 200), neck (100, 150)."""
    p = np.zeros((J, 2), np.float32)
    p[:, 0] = 80 + (np.arange(J) % 5) * 10  # u in 80..120
    p[:, 1] = 120 + np.arange(J) * 4  # v in 120..220
    p[HIPS] = (100, 200)
    p[NECK] = (100, 150)
    return p


def random_poses(shape, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(50, 500, shape + (J, 2)).astype(np.float32)


def test_normalisation_hand_values():
    p = hand_pose()
    p[3] = (150, 100)
    n = normalize_hips_neck(p)
    assert n.scale == pytest.approx(50.0)
    np.testing.assert_allclose(n.shift, [100, 200])
    np.testing.assert_allclose(n.points[3], [1.0, -2.0])
    np.testing.assert_allclose(n.points[HIPS], [0, 0])
    np.testing.assert_allclose(n.points[NECK], [0, -1])
    assert not n.fallback and n.visible.all()


def test_normalisation_round_trip_with_missing_joints_and_fallback_frames():
    p = random_poses((4, 7))
    p[0, 2, 5] = 0  # one missing joint
    p[1, 3, HIPS] = 0  # hips missing -> bbox fallback
    p[2, :, NECK] = 0  # neck missing in a whole clip
    p[3, 4] = 0  # a frame with every joint missing
    n = HipsNeckNormalize()(p)
    assert n.fallback[1, 3] and n.fallback[2].all() and not n.fallback[0].any()
    np.testing.assert_array_equal(n.points[0, 2, 5], [0, 0])
    back = HipsNeckDenormalize()(n)
    np.testing.assert_allclose(back, p, rtol=1e-5, atol=1e-3)
    np.testing.assert_array_equal(back[p == 0], 0)  # missing joints come back exactly (0, 0)
    again = denormalize_hips_neck(n.points, n.shift, n.scale)  # without visibility
    np.testing.assert_allclose(again[0, 0], p[0, 0], rtol=1e-5)


@pytest.mark.parametrize("missing", [HIPS, NECK])
def test_fallback_when_hips_or_neck_missing(missing):
    p = np.zeros((J, 2), np.float32)  # only four joints visible; the rest are missing
    p[[HIPS, NECK, 3, 20]] = [(40, 100), (40, 60), (10, 20), (30, 120)]
    p[missing] = 0
    n = normalize_hips_neck(p)
    lo, hi = p[[i for i in (HIPS, NECK, 3, 20) if i != missing]].min(0), \
        p[[i for i in (HIPS, NECK, 3, 20) if i != missing]].max(0)
    s_b = (hi[1] - lo[1]) / 2  # 50 px: missing (0, 0) joints do not enter the bbox
    assert s_b == 50
    shift = (lo + hi) / 2 + np.array([0, -0.1059 * s_b])
    assert n.fallback
    np.testing.assert_allclose(n.shift, shift, rtol=1e-6)
    assert n.scale == pytest.approx(0.5748 * s_b)
    np.testing.assert_allclose(n.points[20], (p[20] - shift) / (0.5748 * s_b), rtol=1e-5)
    np.testing.assert_array_equal(n.points[missing], [0, 0])


def test_fallback_degenerate_frames_do_not_divide_by_zero():
    empty = np.zeros((J, 2), np.float32)
    n = normalize_hips_neck(empty)
    assert n.scale == 1 and np.all(n.points == 0)
    one = empty.copy()
    one[5] = (7, 9)  # a single visible joint: zero-height bbox
    n = normalize_hips_neck(one)
    assert n.scale == 1 and np.all(np.isfinite(n.points))


def test_joint_bbox_ignores_missing_joints():
    p = hand_pose()
    p[0] = 0
    lo, hi = joint_bbox(p)
    np.testing.assert_allclose(lo, p[1:].min(0))
    np.testing.assert_allclose(hi, p[1:].max(0))


def test_normalisation_3d_hand_values():
    p = np.zeros((2, J, 3), np.float32)
    p[:, HIPS] = (1, 2, 1)
    p[:, NECK] = (1, 2, 1.5)
    p[:, 0] = (1, 2, 0)
    t, shift, scale = normalize_hips_neck_3d(p)
    np.testing.assert_allclose(scale, [0.5, 0.5])
    np.testing.assert_allclose(t[:, 0], [[0, 0, -2]] * 2)
    np.testing.assert_allclose(t[:, NECK], [[0, 0, 1]] * 2)
    np.testing.assert_allclose(shift, [[1, 2, 1]] * 2)


def test_missing_joints_ratio_within_tolerance():
    p = random_poses((400, 30))
    for prob in (0.2944, 0.7187, 0.9328):
        out = MissingJoints(prob)(p, rng=np.random.default_rng(1))
        ratio = np.mean(np.all(out == 0, axis=-1))
        assert abs(ratio - prob) < 0.005, (prob, ratio)  # 312,000 draws: 5 sigma < 0.005
        kept = np.any(out != 0, axis=-1)
        np.testing.assert_array_equal(out[kept], p[kept])  # kept joints are untouched


def test_missing_joints_per_joint_probabilities():
    probs = np.r_[np.zeros(13), np.ones(13)]
    out = MissingJoints(probs)(random_poses((50,)), rng=np.random.default_rng(2))
    assert np.all(out[:, :13] != 0) and np.all(out[:, 13:] == 0)
    with pytest.raises(ValueError, match="26 numbers"):
        MissingJoints([0.5] * 3)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        MissingJoints(1.5)


def test_gaussian_noise_sigma_and_missing_joints_stay_missing():
    p = random_poses((200, 30))
    p[:, :, 7] = 0
    out = GaussianNoise(5.0)(p, rng=np.random.default_rng(3))
    d = (out - p)[:, :, np.arange(J) != 7]
    assert abs(d.std() - 5.0) < 0.05 and abs(d.mean()) < 0.05
    np.testing.assert_array_equal(out[:, :, 7], 0)
    with pytest.raises(ValueError, match="sigma"):
        GaussianNoise(-1)


def test_deform_is_noise_then_missing_and_seeded():
    p = random_poses((10, 5))
    a = Deform(5.0, 0.3)(p, rng=np.random.default_rng(4))
    b = Deform(5.0, 0.3)(p, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    gone = np.all(a == 0, axis=-1)
    assert 0.1 < gone.mean() < 0.5
    assert np.all(np.abs(a[~gone] - p[~gone]) < 40)  # 8 sigma
    np.testing.assert_array_equal(p, random_poses((10, 5)))  # input untouched
    c = Compose([GaussianNoise(5.0), MissingJoints(0.3)])(p, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(a, c)  # the fused pass equals the composition


def test_flip_hand_values_and_flipping_twice_is_identity():
    p = hand_pose()
    p[4] = (100, 50)  # left shoulder
    p[10] = 0  # left eye missing
    out = flip_horizontal(p, 1600)
    np.testing.assert_allclose(out[12], [1500, 50])  # lands on the right shoulder
    np.testing.assert_array_equal(out[11], [0, 0])  # missing left eye -> missing right eye
    np.testing.assert_allclose(out[HIPS], [1500, 200])
    np.testing.assert_array_equal(flip_horizontal(out, 1600), p)
    batch = random_poses((3, 4))
    widths = np.array([1600, 800, 640])
    twice = flip_horizontal(flip_horizontal(batch, widths), widths)
    np.testing.assert_allclose(twice, batch, rtol=0, atol=1e-4)  # float32 rounding of W - u
    perm = np.asarray(FLIP_PERMUTATION)
    assert np.all(perm[perm] == np.arange(J))


def test_random_flip_decides_per_clip():
    p = random_poses((64, 3))
    assert np.array_equal(HorizontalFlip(p=0.0, width=600)(p), p)
    np.testing.assert_array_equal(HorizontalFlip(p=1.0, width=600)(p), flip_horizontal(p, 600))
    out = HorizontalFlip(p=0.5, width=600)(p, rng=np.random.default_rng(5))
    flipped = np.all(out == flip_horizontal(p, 600), axis=(1, 2, 3))
    kept = np.all(out == p, axis=(1, 2, 3))
    assert np.all(flipped ^ kept) and 10 < flipped.sum() < 54
    with pytest.raises(ValueError, match="width"):
        HorizontalFlip()(p)


def test_rotation_hand_values_and_inverse():
    p = np.zeros((J, 2), np.float32)
    p[:] = (10, 10)
    p[HIPS], p[NECK] = (11, 10), (10, 12)
    p[3] = 0  # missing
    out = rotate(p, 90, centre=(10, 10))
    np.testing.assert_allclose(out[HIPS], [10, 11], atol=1e-5)  # +u turns to +v
    np.testing.assert_allclose(out[NECK], [8, 10], atol=1e-5)
    np.testing.assert_array_equal(out[3], [0, 0])
    clip = random_poses((2, 5))
    c = np.array([[200.0, 300.0], [100.0, 50.0]])
    back = rotate(rotate(clip, [7.0, -3.0], c), [-7.0, 3.0], c)
    np.testing.assert_allclose(back, clip, atol=2e-3)


def test_random_rotation_one_angle_per_clip_within_range():
    p = np.repeat(hand_pose()[None, None], 8, 1).repeat(50, 0)  # 50 clips of 8 equal frames
    out = RandomRotation(10)(p, rng=np.random.default_rng(6))
    v0 = p[..., NECK, :] - p[..., HIPS, :]
    v1 = out[..., NECK, :] - out[..., HIPS, :]
    ang = np.degrees(np.arctan2(v1[..., 1], v1[..., 0]) - np.arctan2(v0[..., 1], v0[..., 0]))
    assert np.all(np.abs(ang) <= 10 + 1e-3)
    assert np.allclose(ang, ang[:, :1], atol=1e-3)  # same angle for every frame of a clip
    assert ang[:, 0].std() > 3  # spread over the range
    lo, hi = joint_bbox(p[0], per="clip")
    lo2, hi2 = joint_bbox(out[0], per="clip")
    # the rotation centre (clip bbox centre) is a fixed point: the hand pose is centred on it
    assert np.linalg.norm((lo + hi) / 2 - (lo2 + hi2) / 2) < 15


def test_compose_passes_rng_and_context_and_accepts_torch():
    torch = pytest.importorskip("torch")
    p = random_poses((4, 3))
    t = Compose([HorizontalFlip(1.0), RandomRotation(0.0), GaussianNoise(0.0)])
    out = t(torch.from_numpy(p), rng=np.random.default_rng(0), width=1000)
    assert isinstance(out, torch.Tensor)
    np.testing.assert_allclose(out.numpy(), flip_horizontal(p, 1000), atol=1e-4)
    n = normalize_hips_neck(torch.from_numpy(p))
    assert isinstance(n.points, torch.Tensor) and n.points.dtype == torch.float32
    with pytest.raises(ValueError, match="not callable"):
        Compose([1])
    with pytest.raises(ValueError, match=r"\(\.\.\., J, 2\)"):
        normalize_hips_neck(np.zeros((3, 4)))


def test_fused_flip_rotate_equals_flip_then_rotate():
    p = random_poses((6, 4))
    p[1, 2, 5] = 0
    flip = np.array([True, False, True, True, False, False])
    deg = np.array([10.0, -10.0, 3.0, 0.0, 7.5, -2.0])
    w = np.array([1600, 1600, 800, 640, 1600, 500], np.float32)
    sel = flip[:, None, None, None]
    want = rotate(np.where(sel, flip_horizontal(p, w), p), deg)
    np.testing.assert_allclose(flip_rotate(p, flip, deg, w), want, rtol=1e-5, atol=1e-3)
    one = flip_rotate(p[0], True, 5.0, 1600)
    np.testing.assert_allclose(one, rotate(flip_horizontal(p[0], 1600), 5.0), atol=1e-3)
    # same draws as the composition, so the same output for the same generator
    a = RandomFlipRotate(0.5, 10)(p, rng=np.random.default_rng(9), width=w)
    b = Compose([HorizontalFlip(0.5), RandomRotation(10)])(p, rng=np.random.default_rng(9), width=w)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-3)
