"""bsp_fast.metrics: hand-worked values, slow references written from the definitions,
streaming == one-shot (uneven batches, 2 gloo processes), bad input."""
import math
import socket

import numpy as np
import pytest
import torch

import bsp_fast as bf
from bsp_fast import metrics as M
from bsp_fast import skeleton as sk

torch.set_num_threads(1)
J = 26


# ------------------------------------------------------------------ helpers
def rot(axis, deg):
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def random_rotation(rng):
    q = rng.standard_normal(4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def tpose_mm():
    return bf.forward_kinematics(sk.reference_pose("sk_male"))[:, :3] * 1000


def random_poses(rng, n, noise=40.0):
    """n ground-truth poses (mm) around the T-pose and noisy predictions."""
    gt = tpose_mm() + rng.normal(0, 60, (n, J, 3))
    return gt + rng.normal(0, noise, gt.shape), gt


# ----------------------------------------------------- slow references (definitions)
def ref_mpjpe(p, g):
    return np.mean([np.linalg.norm(a - b) for a, b in zip(p.reshape(-1, 3), g.reshape(-1, 3))])


def ref_n_mpjpe(p, g):
    errs = []
    for a, b in zip(p.reshape(-1, *p.shape[-2:]), g.reshape(-1, *g.shape[-2:])):
        a, b = a - a[sk.HIPS], b - b[sk.HIPS]  # root-relative, each about its own hips
        s = np.sum(a * b) / np.sum(a * a)
        errs += [np.linalg.norm(s * a[j] - b[j]) for j in range(len(a))]
    return np.mean(errs)


def ref_procrustes(a, b):
    """The similarity y -> s y R + t (R proper) minimising sum |s a_j R + t - b_j|^2."""
    ma, mb = a.mean(0), b.mean(0)
    A, B = a - ma, b - mb
    U, S, Vt = np.linalg.svd(B.T @ A)  # B^T A = U S V^T; maximise tr(R B^T A) over R
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    s = np.trace(np.diag(S) @ D) / np.sum(A * A)
    return s, R, mb - s * ma @ R


def ref_pa_mpjpe(p, g):
    errs = []
    for a, b in zip(p.reshape(-1, *p.shape[-2:]), g.reshape(-1, *g.shape[-2:])):
        s, R, t = ref_procrustes(a, b)
        errs += [np.linalg.norm(s * a[j] @ R + t - b[j]) for j in range(len(a))]
    return np.mean(errs)


def ref_mpjve(p, g):
    errs = []
    for a, b in zip(p.reshape(-1, *p.shape[-3:]), g.reshape(-1, *g.shape[-3:])):
        for t in range(1, len(a)):
            for j in range(a.shape[1]):
                errs.append(np.linalg.norm((a[t, j] - a[t - 1, j]) - (b[t, j] - b[t - 1, j])))
    return np.mean(errs)


def ref_pck(p, g, alpha, norm, visible=None):
    hit = n = 0
    p, g = p.reshape(-1, J, 2), g.reshape(-1, J, 2)
    vis = None if visible is None else visible.reshape(-1, J)
    for f in range(len(g)):
        present = [j == sk.HIPS or (g[f, j].any() if vis is None else vis[f, j])
                   for j in range(J)]
        pts = g[f][present]
        if norm == "bbox":
            S = np.linalg.norm(pts.max(0) - pts.min(0))
        else:
            S = np.linalg.norm(g[f, sk.NECK] - g[f, sk.HIPS]) if present[sk.NECK] else 0
        if S < 1e-5:
            continue
        for j in range(J):
            if present[j]:
                n += 1
                hit += np.linalg.norm(p[f, j] - g[f, j]) / S <= alpha
    return hit / n


def ref_f1(pred_labels, target):
    tp = sum(1 for a, b in zip(pred_labels, target) if a == 1 and b == 1)
    fp = sum(1 for a, b in zip(pred_labels, target) if a == 1 and b == 0)
    fn = sum(1 for a, b in zip(pred_labels, target) if a == 0 and b == 1)
    return 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 0.0


# ------------------------------------------------------------- hand-worked values
def test_similarity_transform_gives_zero_pa_and_hand_worked_n_mpjpe():
    # 26 joints on a circle of radius r in the x-z plane; prediction = c * R_y(theta) x
    # + t with t along y (the rotation axis). By hand:
    #   MPJPE^2   = r^2 (c^2 - 2 c cos(theta) + 1) + |t|^2
    #   N-MPJPE: root-relative v_j = x_j - x_hips (t cancels), s = cos(theta) / c, joint
    #   error |cos(theta) R v - v| = sin(theta) |v_j| with |v_j| = 2 r |sin((phi_j -
    #   phi_hips) / 2)|: N-MPJPE = sin(theta) * mean_j 2 r |sin((phi_j - phi_hips) / 2)|
    r, c, theta, ty = 100.0, 1.5, 30.0, 40.0
    phi = 2 * np.pi * np.arange(J) / J
    gt = np.stack([r * np.cos(phi), np.zeros(J), r * np.sin(phi)], -1)
    pred = c * gt @ rot(1, theta).T + [0, ty, 0]
    cos = np.cos(np.deg2rad(theta))
    assert M.mpjpe(pred, gt) == pytest.approx(math.sqrt(r * r * (c * c - 2 * c * cos + 1)
                                                        + ty * ty), rel=1e-12)
    chord = 2 * r * np.abs(np.sin((phi - phi[sk.HIPS]) / 2))
    assert M.n_mpjpe(pred, gt) == pytest.approx(
        np.sin(np.deg2rad(theta)) * chord.mean(), rel=1e-12)
    assert M.pa_mpjpe(pred, gt) == pytest.approx(0, abs=1e-9)
    # a real pose under a random similarity: PA-MPJPE 0 as well, N-MPJPE does not undo it
    rng = np.random.default_rng(3)
    g = tpose_mm()
    p = 0.7 * g @ random_rotation(rng).T + [250.0, -40.0, 900.0]
    assert M.pa_mpjpe(p, g) == pytest.approx(0, abs=1e-9)
    assert M.n_mpjpe(p, g) > 100


def test_reflected_pose_is_not_undone():
    # +-3 e_x, +-2 e_y, +-1 e_z, mirrored in z. The best proper rotation is the identity
    # with the smallest singular value negated: scale = (18 + 8 - 2) / 28 = 6/7, errors
    # 3/7, 2/7 and 13/7 per pair, mean 6/7. Without the fix a mirror "rotation" gives 0.
    gt = np.array([[3, 0, 0], [-3, 0, 0], [0, 2, 0], [0, -2, 0], [0, 0, 1], [0, 0, -1.0]])
    mirrored = gt * [1, 1, -1]
    assert M.pa_mpjpe(mirrored, gt) == pytest.approx(6 / 7, rel=1e-12)
    # invariant to a similarity of the prediction
    moved = 2.5 * mirrored @ rot(2, 70).T + [5, 6, 7]
    assert M.pa_mpjpe(moved, gt) == pytest.approx(6 / 7, rel=1e-12)
    assert M.pa_mpjpe(torch.tensor(moved), torch.tensor(gt)).item() == pytest.approx(6 / 7)


def test_mpjve_stays_inside_clips():
    # clip A: prediction moves 1 unit/frame along x over a still ground truth (error 1
    # per step); clip B: constant offset (velocity error 0). Stacked as two clips: 0.5.
    # The same frames concatenated as one clip would difference across the boundary,
    # (3, 0, 0) -> (5, 0, 0): (3 * 1 + 2 + 3 * 0) / 7.
    L = 4
    gt = np.zeros((2, L, J, 3))
    pred = np.zeros((2, L, J, 3))
    pred[0, :, :, 0] = np.arange(L)[:, None]
    pred[1, :, :, 0] = 5
    assert M.mpjve(pred, gt) == pytest.approx(0.5)
    assert M.mpjve(pred[0], gt[0]) == pytest.approx(1.0)
    assert M.mpjve(pred[1], gt[1]) == pytest.approx(0.0)
    assert M.mpjve(pred.reshape(2 * L, J, 3), gt.reshape(2 * L, J, 3)) == pytest.approx(5 / 7)
    with pytest.raises(ValueError, match=r"\(\.\.\., L, J, 3\) with L >= 2"):
        M.mpjve(pred[:, :1], gt[:, :1])


def test_pck_joint_up_left_of_the_hips():
    # present: hips (100, 200), neck (100, 150) and joint 5 at (60, 120), up-left of the
    # hips; the rest is missing (0, 0). bbox diagonal = |(40, 80)| = 89.44 px -> PCK@0.05
    # threshold 4.47 px; hips-neck 50 px -> PCKhn@0.1 threshold 5 px.
    gt = np.zeros((J, 2))
    gt[sk.HIPS], gt[sk.NECK], gt[5] = (100, 200), (100, 150), (60, 120)
    pred = gt.copy()
    pred[sk.NECK] += (0, 4.0)  # within both
    pred[5] += (-4.8, 0)  # outside 4.47, inside 5
    pred[10] = (300, 300)  # absent in the ground truth: not counted
    assert M.pck(pred, gt, alpha=0.05) == pytest.approx(2 / 3)
    assert M.pck(pred, gt, alpha=0.1, norm="hips_neck") == pytest.approx(1.0)
    c = M.pck_counts(pred, gt, alpha=0.05)
    assert (c.correct, c.total, c.frames, c.skipped) == (2, 3, 1, 0)
    # visible given explicitly: joint 5 marked absent leaves hips + neck, bbox 50 px
    vis = np.zeros(J, bool)
    vis[sk.NECK] = True
    assert M.pck_counts(pred, gt, alpha=0.05, visible=vis).total == 2
    # hips always counted, even when marked absent
    assert M.pck_counts(pred, gt, alpha=0.05, visible=np.zeros(J, bool)).skipped == 1


def test_pck_degenerate_frames_are_left_out_and_counted():
    good = np.zeros((J, 2))
    good[sk.HIPS], good[sk.NECK] = (10, 20), (10, 0)
    only_hips = np.zeros((J, 2))
    only_hips[sk.HIPS] = (50, 50)  # bbox of one point: diagonal 0
    gt = np.stack([good, only_hips, good])
    pred = gt.copy()
    pred[2, sk.NECK] += 3  # |(3, 3)| = 4.2 > 0.05 * 20
    c = M.pck_counts(pred, gt, alpha=0.05)
    assert (c.correct, c.total, c.frames, c.skipped) == (3, 4, 2, 1)
    assert M.pck(pred, gt, alpha=0.05) == pytest.approx(0.75)
    # hips_neck: the frame without a neck is skipped too
    assert M.pck_counts(pred, gt, alpha=0.1, norm="hips_neck").skipped == 1
    assert np.isnan(M.pck(pred[1:2], gt[1:2], alpha=0.05))


def test_classification_hand_values():
    target = np.array([1, 0, 1, 0])
    none = np.zeros(4, int)
    assert M.f1_score(none, target) == 0.0
    assert M.precision(none, target) == 0.0 and M.recall(none, target) == 0.0
    assert M.accuracy(none, target) == 0.5
    np.testing.assert_array_equal(M.confusion_matrix(none, target), [[2, 0], [2, 0]])
    # one logit: sigmoid >= 0.5 <=> logit >= 0 (0.3 is positive, -0.2 negative)
    logits = np.array([0.3, -0.2, -1.0, 2.0])  # -> 1, 0, 0, 1: tp 1, fp 1, fn 1, tn 1
    assert M.f1_score(logits, target) == pytest.approx(0.5)
    two = torch.tensor([[0.0, 1.0], [2.0, -1.0], [0.5, 0.4], [0.1, 0.2]])  # -> 1, 0, 0, 1
    assert M.f1_score(two, torch.tensor(target)).item() == pytest.approx(0.5)
    assert M.f1_score(target.astype(bool), target) == 1.0


def test_nan_and_missing_handling():
    rng = np.random.default_rng(0)
    p, g = random_poses(rng, 3)
    p[1, 4, 0] = np.nan
    assert np.isnan(M.mpjpe(p, g)) and np.isnan(M.n_mpjpe(p, g)) and np.isnan(M.pa_mpjpe(p, g))
    assert M.pa_mpjpe(p[[0, 2]], g[[0, 2]]) == pytest.approx(ref_pa_mpjpe(p[[0, 2]], g[[0, 2]]))
    # PCK: a NaN prediction is a miss; a NaN ground-truth joint is not counted
    gt2 = rng.uniform(50, 300, (J, 2))
    pr2 = gt2.copy()
    pr2[3] = np.nan
    assert M.pck_counts(pr2, gt2, alpha=0.05)[:2] == (J - 1, J)
    gt2[3] = np.nan
    assert M.pck_counts(pr2, gt2, alpha=0.05)[:2] == (J - 1, J - 1)
    # masked MSE ignores what the mask leaves out, even NaN
    a, b = np.ones((2, J, 2)), np.zeros((2, J, 2))
    a[0, 0] = np.nan
    mask = np.ones((2, J), bool)
    mask[0, 0] = False
    assert M.masked_mse(a, b, mask) == 1.0
    assert np.isnan(M.masked_mse(a, b))
    with pytest.raises(ValueError, match="NaN"):
        M.f1_score(np.array([0.1, np.nan]), np.array([0, 1]))
    vis = np.ones((4, J), bool)
    vis[0, :13] = False
    assert M.missing_joint_ratio(vis) == pytest.approx(13 / (4 * J))


def test_degenerate_procrustes_frames():
    # prediction collapsed to a point: best scale 0, error = distance to the gt centroid;
    # collinear prediction: handled by the library fallback, equal to the reference
    rng = np.random.default_rng(5)
    g = tpose_mm() + rng.normal(0, 30, (3, J, 3))
    p = g.copy()
    p[0] = 7.0
    p[1] = np.outer(np.arange(J), [1.0, 2.0, 3.0])
    p[2] = g[2] * [1, 1, 1e-14]  # almost planar
    expected = np.mean(np.linalg.norm(g[0] - g[0].mean(0), axis=-1))
    assert M.pa_mpjpe(p[:1], g[:1]) == pytest.approx(expected, rel=1e-12)
    assert M.pa_mpjpe(p[1:], g[1:]) == pytest.approx(ref_pa_mpjpe(p[1:], g[1:]), rel=1e-9)


def test_lifting_denormalisation_rule():
    hn = sk.hips_neck_length("adult", "female")
    ref = sk.reference_pose("sk_female", "absolute")[:, :3]  # shipped FK result
    assert hn == pytest.approx(np.linalg.norm(ref[sk.NECK] - ref[sk.HIPS]), abs=2e-6)
    lengths = sk.hips_neck_length(["child", "child", "adult"], ["female", "male", "male"])
    np.testing.assert_allclose(lengths, [0.2835, 0.3201, 0.4673], atol=1e-4)
    with pytest.raises(ValueError, match="allowed"):
        sk.hips_neck_length("teen", "female")
    # a normalised pose: hips at 0, neck 1 above; target hips at (1, 2, 3) m
    pred = np.zeros((2, 3, J, 3), np.float32)
    pred[..., sk.NECK, 2] = 1.0
    gt = np.zeros((2, 3, J, 3))
    gt[..., sk.HIPS, :] = (1, 2, 3)
    out = M.denormalise_lifting(pred, gt, np.array([0.5, 0.25]))
    np.testing.assert_allclose(out[0, :, sk.NECK], [[1, 2, 3.5]] * 3)
    np.testing.assert_allclose(out[1, :, sk.HIPS], [[1, 2, 3]] * 3)
    np.testing.assert_allclose(out[1, :, sk.NECK], [[1, 2, 3.25]] * 3)
    per_frame = M.denormalise_lifting(torch.tensor(pred), torch.tensor(gt), torch.ones(2, 3))
    assert per_frame.dtype == torch.float32 and per_frame[0, 0, sk.NECK, 2] == 4.0
    r = M.root_align(pred + 9, gt)
    np.testing.assert_allclose(r[..., sk.HIPS, :], gt[..., sk.HIPS, :])
    with pytest.raises(ValueError, match=r"prefix of the leading axes"):
        M.denormalise_lifting(pred, gt, np.ones(3))


# ------------------------------------------------------ independent random checks
def test_pose3d_against_slow_references():
    rng = np.random.default_rng(1)
    p, g = random_poses(rng, 40)
    p[:10] = p[:10] * [1, -1, 1]  # mirrored predictions exercise the reflection fix
    assert M.mpjpe(p, g) == pytest.approx(ref_mpjpe(p, g), rel=1e-12)
    assert M.n_mpjpe(p, g) == pytest.approx(ref_n_mpjpe(p, g), rel=1e-12)
    assert M.pa_mpjpe(p, g) == pytest.approx(ref_pa_mpjpe(p, g), rel=1e-10)
    clips = (p.reshape(5, 8, J, 3), g.reshape(5, 8, J, 3))
    assert M.mpjve(*clips) == pytest.approx(ref_mpjve(*clips), rel=1e-12)
    # torch in -> float64 tensor out, same value; float32 inputs accumulate in float64
    t = M.pa_mpjpe(torch.tensor(p, dtype=torch.float32), torch.tensor(g, dtype=torch.float32))
    assert t.dtype == torch.float64 and t.item() == pytest.approx(ref_pa_mpjpe(p, g), rel=1e-5)
    assert isinstance(M.mpjpe(p, g), np.float64)
    # the torch implementation of the batched Procrustes (used on GPUs), run on the CPU
    from bsp_fast.metrics import _arrays, pose3d

    tp, tg = torch.tensor(p), torch.tensor(g)
    total = pose3d._pa_total(_arrays.Kind(tp, tg), tp, tg, chunk=16)
    assert total.item() / p[..., 0].size == pytest.approx(ref_pa_mpjpe(p, g), rel=1e-10)


def test_reference_procrustes_is_optimal():
    # the reference itself: no nearby proper rotation/scale does better in least squares
    rng = np.random.default_rng(2)
    p, g = random_poses(rng, 1)
    p[0] *= [1, 1, -1]
    s, R, t = ref_procrustes(p[0], g[0])
    best = np.sum((s * p[0] @ R + t - g[0]) ** 2)
    for _ in range(50):
        w = rng.normal(0, 0.02, 3)
        u, _, vt = np.linalg.svd(np.eye(3) + np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]],
                                                       [-w[1], w[0], 0]]))
        R2 = R @ u @ vt  # a nearby proper rotation
        s2 = s * (1 + rng.normal(0, 0.02))
        t2 = g[0].mean(0) - s2 * p[0].mean(0) @ R2
        assert np.sum((s2 * p[0] @ R2 + t2 - g[0]) ** 2) >= best - 1e-6


def test_pck_and_f1_against_slow_references():
    rng = np.random.default_rng(4)
    g = rng.uniform(100, 500, (30, J, 2))
    g[rng.random((30, J)) < 0.2] = 0
    g[5] = 0
    g[5, sk.HIPS] = (200, 200)  # degenerate frame
    p = g + rng.normal(0, 6, g.shape)
    for alpha, norm in ((0.05, "bbox"), (0.1, "hips_neck"), (0.02, "bbox")):
        assert M.pck(p, g, alpha=alpha, norm=norm) == pytest.approx(ref_pck(p, g, alpha, norm))
    vis = rng.random((30, J)) < 0.7
    assert M.pck(p, g, alpha=0.05, visible=vis) == pytest.approx(ref_pck(p, g, 0.05, "bbox", vis))
    logits = rng.normal(0, 1, (200, 2))
    target = rng.integers(0, 2, 200)
    assert M.f1_score(logits, target) == pytest.approx(ref_f1(np.argmax(logits, 1), target))


# --------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, expected", [
    (lambda: M.mpjpe(np.zeros((4, J, 3)), np.zeros((4, J, 2))), r"\(\.\.\., J, 3\)"),
    (lambda: M.pa_mpjpe(np.zeros((4, J, 3)), np.zeros((5, J, 3))), r"same shape \(\.\.\., J, 3\)"),
    (lambda: M.n_mpjpe(np.zeros((0, J, 3)), np.zeros((0, J, 3))), r"\(\.\.\., J, 3\)"),
    (lambda: M.mpjve(np.zeros((J, 3)), np.zeros((J, 3))), r"\(\.\.\., L, J, 3\)"),
    (lambda: M.pck(np.zeros((2, 17, 2)), np.zeros((2, 17, 2)), alpha=0.05), r"\(\.\.\., 26, 2\)"),
    (lambda: M.pck(np.zeros((J, 2)), np.zeros((J, 2)), alpha=0.05, visible=np.ones(3, bool)),
     r"\(26,\)"),
    (lambda: M.pck(np.zeros((J, 2)), np.zeros((J, 2)), alpha=0.05, norm="box"), "hips_neck"),
    (lambda: M.pck(np.zeros((J, 2)), np.zeros((J, 2)), alpha=-1), "alpha"),
    (lambda: M.f1_score(np.zeros((3, 3)), np.zeros(3, int)), r"\(N, 2\) logits"),
    (lambda: M.f1_score(np.zeros(3, int), np.zeros(4, int)), "same N"),
    (lambda: M.f1_score(np.array([0, 2]), np.array([0, 1])), r"labels in \{0, 1\}"),
    (lambda: M.accuracy(np.zeros(0, int), np.zeros(0, int)), r"\(N,\) labels"),
    (lambda: M.masked_mse(np.zeros((2, J, 2)), np.zeros((2, J, 2)), np.ones(J, bool)),
     r"\(2, 26\) \(per joint\)"),
])
def test_bad_input_names_the_expected_shape(call, expected):
    with pytest.raises(ValueError, match=expected):
        call()


# ------------------------------------------------------------------ streaming
def _cuts(n, rng):
    cuts = np.sort(rng.choice(np.arange(1, n), 4, replace=False))
    return [slice(a, b) for a, b in zip([0, *cuts], [*cuts, n])]


def _stream_cases(rng):
    """(metric, update argument tuples over the whole split, one-shot value)."""
    p, g = random_poses(rng, 60)
    clips = (p.reshape(12, 5, J, 3), g.reshape(12, 5, J, 3))
    g2 = rng.uniform(0, 400, (60, J, 2))
    g2[rng.random((60, J)) < 0.3] = 0
    p2 = g2 + rng.normal(0, 8, g2.shape)
    logits, target = rng.normal(0, 1, (60, 2)), rng.integers(0, 2, 60)
    vis = rng.random((60, J)) < 0.8
    from bsp_fast.metrics import streaming as S

    return [
        (S.MPJPE(), (p, g), M.mpjpe(p, g)),
        (S.NMPJPE(), (p, g), M.n_mpjpe(p, g)),
        (S.PAMPJPE(), (p, g), M.pa_mpjpe(p, g)),
        (S.MPJVE(), clips, M.mpjve(*clips)),
        (S.PCK(0.05), (p2, g2), M.pck(p2, g2, alpha=0.05)),
        (S.PCK(0.1, "hips_neck"), (p2, g2), M.pck(p2, g2, alpha=0.1, norm="hips_neck")),
        (S.MaskedMSE(), (p2, g2, vis), M.masked_mse(p2, g2, vis)),
        (S.MissingJointRatio(), (vis,), M.missing_joint_ratio(vis)),
        (S.ClassificationMetrics(), (logits, target), M.f1_score(logits, target)),
    ]


def _value(metric):
    out = metric.compute()
    return float(out["f1"] if isinstance(out, dict) else out)


def test_streaming_equals_one_shot_on_uneven_batches():
    rng = np.random.default_rng(7)
    for metric, args, one_shot in _stream_cases(rng):
        n = len(args[0])
        for k, part in enumerate(_cuts(n, rng)):
            batch = [a[part] for a in args]
            metric.update(*(torch.tensor(b) if k % 2 else b for b in batch))
        assert _value(metric) == pytest.approx(float(one_shot), rel=1e-12), type(metric)
    with pytest.warns(UserWarning, match="before the ``update``"):
        assert math.isnan(float(M.MPJPE().compute()))
    pck = M.PCK(0.05)
    g = np.zeros((2, J, 2))
    g[:, sk.HIPS] = 5
    g[1, 3] = (40, 40)
    pck.update(g, g)
    assert (pck.scored_frames, pck.skipped_frames, float(pck.compute())) == (1, 1, 1.0)
    with pytest.raises(ValueError, match="norm"):
        M.PCK(norm="diag")


def _ddp_rank(rank, port):
    import torch.distributed as dist

    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank,
                            world_size=2)
    try:
        cases = _stream_cases(np.random.default_rng(11))  # same data on both ranks
        for metric, args, one_shot in cases:
            n = len(args[0])
            cut = 2 * n // 5  # uneven shares
            share = slice(0, cut) if rank == 0 else slice(cut, n)
            metric.update(*(a[share] for a in args))
            got = _value(metric)
            assert got == pytest.approx(float(one_shot), rel=1e-12), (type(metric), got)
    finally:
        dist.destroy_process_group()


def test_streaming_reduces_across_two_gloo_processes():
    import torch.multiprocessing as mp

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    # fork: the children inherit the imported torch/torchmetrics (spawn re-imports them,
    # ~10 s on a busy 2-core machine)
    mp.start_processes(_ddp_rank, args=(port,), nprocs=2, start_method="fork")
