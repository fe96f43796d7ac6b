"""Geometry API against hand-computed values and an independent NumPy implementation."""
import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast import skeleton as sk


# ---------------------------------------------------------------- NumPy reference
def np_rot(pyr):
    p, y, r = np.deg2rad(pyr[..., 0]), np.deg2rad(pyr[..., 1]), np.deg2rad(pyr[..., 2])
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    R = np.empty(pyr.shape[:-1] + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = sp, -cp * sr, cp * cr
    return R


def elementary(pyr):
    """Rz(yaw) Ry(-pitch) Rx(-roll) from right-handed elementary matrices
    (docs/dataset-format.md, "5. Geometry conventions")."""
    p, y, r = np.deg2rad(pyr)
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(-p), 0, np.sin(-p)], [0, 1, 0], [-np.sin(-p), 0, np.cos(-p)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(-r), -np.sin(-r)], [0, np.sin(-r), np.cos(-r)]])
    return Rz @ Ry @ Rx


def np_fk(rel, parents):
    R = np_rot(rel[..., 3:])
    t = rel[..., :3]
    AR, At = np.empty_like(R), np.empty_like(t)
    AR[..., 0, :, :], At[..., 0, :] = R[..., 0, :, :], t[..., 0, :]
    for j in range(1, rel.shape[-2]):
        p = parents[j]
        AR[..., j, :, :] = AR[..., p, :, :] @ R[..., j, :, :]
        At[..., j, :] = np.einsum("...ab,...b->...a", AR[..., p, :, :], t[..., j, :]) + At[..., p, :]
    return AR, At


def np_project(pts, cam, W, H, fov):
    R = np_rot(cam[..., 3:])
    c = np.einsum("...ba,...jb->...ja", R, pts - cam[..., None, :3])
    f = W / (2 * np.tan(np.deg2rad(fov) / 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([W / 2 + f * c[..., 1] / c[..., 0], H / 2 - f * c[..., 2] / c[..., 0]], -1)
    uv[c[..., 0] <= 0] = np.nan
    return uv


def random_transforms(rng, shape, pitch_max=85):
    t = np.empty(shape + (6,))
    t[..., :3] = rng.normal(0, 5, shape + (3,))
    t[..., 3] = rng.uniform(-pitch_max, pitch_max, shape)
    t[..., 4:] = rng.uniform(-179, 179, shape + (2,))
    return t


# ---------------------------------------------------------------- rotations
def test_rotation_matrix_matches_elementary_product():
    rng = np.random.default_rng(0)
    for pyr in random_transforms(rng, (20,))[:, 3:]:
        np.testing.assert_allclose(bf.rotation_matrix(pyr), elementary(pyr), atol=1e-12)


def test_known_rotations():
    np.testing.assert_allclose(bf.rotation_matrix([0, 90, 0]) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(bf.rotation_matrix([90, 0, 0]) @ [1, 0, 0], [0, 0, 1], atol=1e-12)


def test_euler_round_trip():
    rng = np.random.default_rng(1)
    pyr = random_transforms(rng, (1000,), pitch_max=89)[:, 3:]
    back = bf.rotation_to_euler(bf.rotation_matrix(pyr))
    assert np.abs(back - pyr).max() < 1e-6


def test_batched_shapes_follow_input():
    pyr = np.zeros((2, 3, 4, 3))
    assert bf.rotation_matrix(pyr).shape == (2, 3, 4, 3, 3)
    assert bf.rotation_to_euler(bf.rotation_matrix(pyr)).shape == (2, 3, 4, 3)


# ---------------------------------------------------------------- transforms
def test_compose_invert_identities():
    rng = np.random.default_rng(2)
    a, b = random_transforms(rng, (50,)), random_transforms(rng, (50,))
    ident = bf.compose(a, bf.invert(a))
    np.testing.assert_allclose(bf.rotation_matrix(ident[:, 3:]), np.broadcast_to(np.eye(3), (50, 3, 3)), atol=1e-9)
    np.testing.assert_allclose(ident[:, :3], 0, atol=1e-9)
    p = rng.normal(size=(50, 3))
    np.testing.assert_allclose(bf.transform_points(bf.compose(a, b), p),
                               bf.transform_points(a, bf.transform_points(b, p)), atol=1e-9)


def test_broadcasting_one_transform_many_points():
    rng = np.random.default_rng(3)
    t = random_transforms(rng, (4,))
    p = rng.normal(size=(4, 26, 3))
    out = bf.transform_points(t[:, None, :], p)
    ref = np.einsum("nab,njb->nja", np_rot(t[:, 3:]), p) + t[:, None, :3]
    np.testing.assert_allclose(out, ref, atol=1e-12)
    # a single transform against a batch, and a batch against a single point
    np.testing.assert_allclose(bf.transform_points(t[0], p)[1], bf.transform_points(t[0], p[1]))
    assert bf.transform_points(t, p[0, 0]).shape == (4, 3)


# ---------------------------------------------------------------- kinematics
def test_fk_reproduces_reference_absolute_pose():
    rel = sk.reference_pose("sk_female")
    ab = sk.reference_pose("sk_female", "absolute")
    A = bf.forward_kinematics(rel)
    assert np.abs(A[:, :3] - ab[:, :3]).max() * 100 < 1e-4  # centimetres
    assert np.abs(bf.rotation_matrix(A[:, 3:]) - bf.rotation_matrix(ab[:, 3:])).max() < 1e-4


def test_fk_against_numpy_on_random_batches():
    rng = np.random.default_rng(4)
    rel = random_transforms(rng, (7, 3, 26))
    root = random_transforms(rng, (7, 3))
    A = bf.forward_kinematics(rel, root=root)
    # independent: prepend root as an extra bone 0 of a 27-joint tree
    parents27 = [-1, 0] + [p + 1 for p in sk.PARENTS[1:]]
    R, t = np_fk(np.concatenate([root[..., None, :], rel], -2), parents27)
    np.testing.assert_allclose(A[..., :3], t[..., 1:, :], atol=1e-9)
    np.testing.assert_allclose(bf.rotation_matrix(A[..., 3:]), R[..., 1:, :, :], atol=1e-9)


def test_fk_custom_parents_and_errors():
    rel = np.zeros((3, 6))
    rel[:, 0] = 1.0  # each bone 1 m along its parent's x
    chain = bf.forward_kinematics(rel, parents=[-1, 0, 1])
    np.testing.assert_allclose(chain[:, 0], [1, 2, 3])
    star = bf.forward_kinematics(rel, parents=[-1, 0, 0])
    np.testing.assert_allclose(star[:, 0], [1, 2, 2])
    with pytest.raises(ValueError, match="parent"):
        bf.forward_kinematics(rel, parents=[-1, 2, 0])
    with pytest.raises(ValueError, match=r"\(\.\.\., 26, 6\)"):
        bf.forward_kinematics(np.zeros((25, 6)))


def test_mesh_offset_and_to_world_recover_the_dataset_relations():
    rng = np.random.default_rng(5)
    rel = np.broadcast_to(sk.reference_pose("sk_male"), (10, 26, 6)).copy()
    rel[:, 1:, 3:] += rng.normal(0, 10, (10, 25, 3))
    M = np.array([0, 0, -0.92, 0, -90, 0])
    comp = bf.forward_kinematics(rel, root=M)
    np.testing.assert_allclose(bf.mesh_offset(rel, comp), np.broadcast_to(M, (10, 6)), atol=1e-9)
    walker = random_transforms(rng, (10,))
    world = bf.to_world(comp, walker)
    np.testing.assert_allclose(world[..., :3], bf.transform_points(walker[:, None], comp[..., :3]), atol=1e-9)


# ---------------------------------------------------------------- projection
def test_projection_by_hand():
    cam = np.array([0, 0, 0, 0, 0, 0.0])
    pts = np.array([[[10, 0, 0], [10, 1, 0], [10, 0, 1], [-1, 0, 0]]], float)
    uv = bf.project(pts, cam[None], 1600, 600)
    np.testing.assert_allclose(uv[0, 0], [800, 300])
    np.testing.assert_allclose(uv[0, 1], [880, 300])  # f/10 px right of centre (f = 800)
    np.testing.assert_allclose(uv[0, 2], [800, 220])
    assert np.isnan(uv[0, 3]).all()
    # fov 60 -> f = 800 / tan(30 deg)
    f = 800 / np.tan(np.deg2rad(30))
    np.testing.assert_allclose(bf.project(pts[:, 1:2], cam, 1600, 600, fov=60)[0, 0], [800 + f / 10, 300])


def test_projection_against_numpy():
    rng = np.random.default_rng(6)
    cam = random_transforms(rng, (5,), pitch_max=30)
    pts = cam[:, None, :3] + rng.normal(0, 8, (5, 26, 3))
    np.testing.assert_allclose(bf.project(pts, cam, 1600, 600), np_project(pts, cam, 1600, 600, 90),
                               atol=1e-7, equal_nan=True)


def test_in_frame_loose_rule():
    uv = np.array([
        [[10, 10], [20, 20]],
        [[-5, 700], [1700, -3]],   # corners outside, but each test passes once
        [[-5, 10], [-1, 20]],      # no u >= 0
        [[10, 10], [np.nan, np.nan]],
    ])
    assert bf.in_frame(uv, 1600, 600).tolist() == [True, True, False, False]


# ---------------------------------------------------------------- errors
def test_bad_shapes_and_dtypes():
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 3\)"):
        bf.rotation_matrix(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        bf.rotation_to_euler(np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        bf.compose(np.zeros(5), np.zeros(6))
    with pytest.raises(ValueError, match="broadcast"):
        bf.compose(np.zeros((3, 6)), np.zeros((4, 6)))
    with pytest.raises(ValueError, match=r"\(\.\.\., J, 3\)"):
        bf.project(np.zeros(3), np.zeros(6), 100, 100)
    with pytest.raises(ValueError, match="fov"):
        bf.project(np.zeros((1, 3)), np.zeros(6), 100, 100, fov=180)
    with pytest.raises(TypeError, match="dtype"):
        bf.rotation_matrix(np.array(["a", "b", "c"]))


def test_float32_input_and_threads_give_identical_results():
    rng = np.random.default_rng(7)
    rel = random_transforms(rng, (3000, 26)).astype(np.float32)
    bf.set_num_threads(1)
    one = bf.forward_kinematics(rel)
    bf.set_num_threads(2)
    two = bf.forward_kinematics(rel)
    bf.set_num_threads(0)
    assert one.dtype == np.float64
    np.testing.assert_array_equal(one, two)


# ---------------------------------------------------------------- skeleton
def test_skeleton_tables():
    assert len(sk.JOINT_NAMES) == 26 and sk.JOINT_NAMES[sk.NECK] == "crl_neck__C"
    names, parents = sk.structure_parents()
    assert names == sk.JOINT_NAMES and parents == sk.PARENTS
    flip = np.array(sk.FLIP_PERMUTATION)
    np.testing.assert_array_equal(flip[flip], np.arange(26))  # an involution
    for i, n in enumerate(sk.JOINT_NAMES):  # left <-> right names swap
        assert sk.JOINT_NAMES[flip[i]] == n.replace("__L", "__X").replace("__R", "__L").replace("__X", "__R")


@pytest.mark.parametrize("profile,hn", [(("adult", "female"), 0.467), (("adult", "male"), 0.467),
                                        (("child", "female"), 0.284), (("child", "male"), 0.320)])
def test_reference_sizes(profile, hn):
    A = bf.forward_kinematics(sk.reference_pose(profile))
    assert abs(np.linalg.norm(A[sk.NECK, :3] - A[sk.HIPS, :3]) - hn) < 1e-3


def test_diagnostics_lists_libraries():
    d = bf.diagnostics()
    for key in ("bsp_fast", "ffmpeg", "opencv", "hdf5", "eigen", "assimp"):
        assert d[key]


def test_gimbal_lock_matrices_round_trip_in_batches():
    pyr = np.array([[90, 30, 20], [-90, -45, 10], [90, 0, 0]] * 100, float)
    R = bf.rotation_matrix(pyr)
    back = bf.rotation_to_euler(R)
    assert np.all(back[:, 2] == 0)  # roll folded into yaw at gimbal lock
    np.testing.assert_allclose(bf.rotation_matrix(back), R, atol=1e-9)


def test_nan_propagates_through_batches():
    rel = np.tile(sk.reference_pose("sk_female"), (3, 1, 1))
    rel[1, 4, 3] = np.nan
    A = bf.forward_kinematics(rel)
    assert np.isfinite(A[0]).all() and np.isfinite(A[2]).all()
    assert np.isnan(A[1, 4:8, 3:]).any()  # the bone and its descendants
