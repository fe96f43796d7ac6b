"""bsp-synth building blocks: options, street, walker, gait, body, renderer bindings."""
from __future__ import annotations

import numpy as np
import pytest

import bsp_fast
from bsp_fast import geometry as geo
from bsp_fast.skeleton import JOINT_INDEX as J
from bsp_fast.synth import body, gait, scene, walker
from bsp_fast.synth.config import load_yaml_config, make_config, parse_profiles, parse_size
from bsp_fast.synth.motion import min_rotation


def test_presets_and_overrides():
    s = make_config("sample")
    assert (s.number_of_clips, s.width, s.height, s.camera_fov) == (20, 640, 240, 90.0)
    m = make_config("medium")
    assert (m.number_of_clips, m.clip_length_in_frames, m.width, m.height) == (160, 300, 1600, 600)
    f = make_config("full")
    assert (f.number_of_clips, f.clip_length_in_frames, f.width, f.height) == (396, 900, 1600, 600)
    c = make_config("full", dict(number_of_clips=3, camera_image_size="320x128"))
    assert (c.number_of_clips, c.width, c.clip_length_in_frames) == (3, 320, 900)


@pytest.mark.parametrize("bad, match", [
    (dict(number_of_clips=0), "number_of_clips"),
    (dict(camera_image_size="641x240"), "even"),
    (dict(camera_fov=180.0), "camera_fov"),
    (dict(seed=-1), "seed"),
    (dict(crossing_probability=1.5), "crossing_probability"),
    (dict(bogus=1), "unknown options"),
])
def test_bad_options_raise_value_error(bad, match):
    with pytest.raises(ValueError, match=match):
        make_config("sample", bad)
    with pytest.raises(ValueError, match="preset"):
        make_config("huge")


def test_profiles_as_the_original_generator_wrote_them():
    p = parse_profiles([["adult_male", 3], [["child", "female", [0.9, 0.19], [1.1, 0.2]], 1]])
    assert [x.name for x, _ in p] == ["adult_male", "child_female"]
    assert [w for _, w in p] == [0.75, 0.25]
    assert p[1][0].crossing_speed == (1.1, 0.2)
    with pytest.raises(ValueError, match="age must be one of"):
        parse_profiles([[["elder", "female", [1, 0], [1, 0]], 1]])
    with pytest.raises(ValueError, match="unknown profile"):
        parse_profiles([["teen", 1]])


def test_yaml_keys(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("number_of_clips: 5\ncamera_distances_distributions: [[[-7, 2], [0, 0.25], "
                 "[1, 0.25]]]\noutputs_dir: ignored\nwaypoint_jitter_scale: 2.0\n")
    o = load_yaml_config(f)
    assert o["number_of_clips"] == 5 and "outputs_dir" not in o
    assert o["camera_position_distributions"] == [[[-7, 2], [0, 0.25], [1, 0.25]]]
    assert o["look_at_shift"] == (3.0, 6.0)
    f.write_text("number_of_clip: 5\n")
    with pytest.raises(ValueError, match="unknown keys"):
        load_yaml_config(f)
    assert parse_size("1600x600") == (1600, 600) and parse_size([64, 48]) == (64, 48)


def test_street_cross_section():
    st = scene.sample_street(np.random.default_rng(1))
    lo, hi = st.driving_bounds()
    elo, ehi = st.road_edges()
    assert elo <= lo < 0 < hi <= ehi
    assert st.on_driving_lane([lo, 0.0, hi]).all() and not st.on_driving_lane([hi + 0.01]).any()
    np.testing.assert_allclose(st.ground_height([0.0, ehi + 2, elo - 2]), [0, scene.CURB,
                                                                           scene.CURB])
    p = st.to_world(3.0, -2.0, 0.5)
    np.testing.assert_allclose(st.to_road(p), [3.0, -2.0], atol=1e-12)
    for side in (-1, 1):
        inner, outer = st.sidewalk_bounds(side)
        assert inner < outer <= st.building_line(side)


def test_camera_looks_at_the_lane_point():
    look = np.array([10.0, 5.0, 0.0])
    cam = scene.look_at_camera(look, 30.0, np.array([-7.0, 0.0, 1.0]))
    assert cam[5] == 0.0
    np.testing.assert_allclose(cam[4], 30.0, atol=1e-9)
    np.testing.assert_allclose(cam[3], -np.degrees(np.arctan2(1.0, 7.0)), atol=1e-9)
    W, H = 1600, 600
    uv = geo.project(look[None], cam, W, H, 90.0)
    np.testing.assert_allclose(uv[0], [W / 2, H / 2], atol=1e-6)  # look-at point at centre


def test_walker_reaches_waypoint_at_constant_speed():
    rng = np.random.default_rng(4)
    st = scene.sample_street(rng)
    plan = walker.plan_clip(rng, st, True, (3.0, 0.0), 5.0)
    path = walker.simulate(plan, st, 1.2, 600, 30.0, 0.92, 1.0, rng)
    d = np.linalg.norm(path.sw - plan.look_at_sw, axis=1)
    assert d.min() < 1.0  # walked to the look-at point on the lane
    step = np.linalg.norm(np.diff(path.sw, axis=0), axis=1) * 30
    np.testing.assert_allclose(step, 1.2, rtol=1e-9)
    assert path.on_lane.any() and not path.on_lane[0]  # starts on the sidewalk
    assert np.all(np.abs(path.sw[:, 1]) <= max(st.building_line(-1), st.building_line(1)))
    z = path.xyz[:, 2] - 0.92
    assert np.all((z >= -1e-9) & (z <= scene.CURB + 1e-9))
    par = walker.plan_clip(rng, st, False, (3.0, 0.0), 5.0)
    assert par.waypoints_sw[0][1] == par.spawn_sw[1]  # parallel to the lane
    assert abs(par.waypoints_sw[0][0] - par.spawn_sw[0]) <= 5.0


def test_cadence_follows_speed_and_size():
    adult = gait.reference("sk_male")[1][J["crl_thigh__R"], 2]
    kid = gait.reference("sk_kid")[1][J["crl_thigh__R"], 2]
    s1, c1 = gait.cadence(1.0, adult)
    s2, c2 = gait.cadence(1.6, adult)
    s3, c3 = gait.cadence(1.0, kid)
    assert s2 > s1 and c2 > c1  # faster: longer and quicker steps
    assert c3 > c1 and s3 < s1  # children: shorter legs, higher cadence
    assert 1.6 < c1 < 2.2 and 0.4 < s1 < 0.8


def test_gait_keeps_bone_lengths_and_ground_contact():
    for stem in ("sk_female", "sk_girl"):
        rel = gait.walk(stem, 1.3, 90, 30.0, gait.GaitStyle())
        ref = np.array(bsp_fast.skeleton.reference_pose(stem))
        np.testing.assert_allclose(rel[:, 2:, :3],
                                   np.broadcast_to(ref[2:, :3], rel[:, 2:, :3].shape))
        mesh = geo.forward_kinematics(rel)
        lowest = mesh[:, [19, 20, 24, 25], 2].min(axis=1)
        assert np.all(lowest > -0.02) and np.all(lowest < 0.05)
        swing = mesh[:, J["crl_foot__L"], 1] - mesh[:, J["crl_foot__R"], 1]
        assert swing.max() > 0.15 and swing.min() < -0.15  # legs alternate
        # the left eye stays on the body's left (mesh +x), toes point forward (+y)
        assert np.all(mesh[:, J["crl_eye__R"], 0] < 0.01)
        assert np.all(mesh[:, J["crl_toeEnd__L"], 1] > mesh[:, J["crl_foot__L"], 1] - 0.05)


def test_mesh_offset_depends_on_the_model():
    np.testing.assert_allclose(gait.mesh_offset_transform("sk_male"), [0, 0, -0.92, 0, -90, 0])
    assert -0.6 < gait.mesh_offset_transform("sk_girl")[2] < -0.5


def test_min_rotation():
    a = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
    b = np.array([[0, 1.0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    R = min_rotation(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", R, a), b, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0)


def test_body_capsules_scale_with_the_model():
    for stem, top in (("sk_female", 1.7), ("sk_kid", 1.15)):
        rel = gait.walk(stem, 1.0, 2, 30.0, gait.GaitStyle())
        comp = geo.forward_kinematics(rel, root=gait.mesh_offset_transform(stem))
        walker_tf = np.array([5.0, 2.0, gait.capsule_half_height(stem), 0, 0, 0])
        w = geo.to_world(comp, walker_tf)
        caps = body.body_capsules(w[..., :3], np.array([[1.0, 0, 0]] * 2))
        assert caps.shape == (2, len(body.PARTS), 7)
        height = (caps[..., [2, 5]].max(-1) + caps[..., 6]).max()
        assert abs(height - top) < 0.12
    cols = body.sample_colours(np.random.default_rng(0))
    assert cols.shape == (len(body.PARTS), 3) and cols.min() >= 0 and cols.max() <= 255


def test_render_bindings_check_shapes():
    core = bsp_fast._core
    z = np.zeros
    light = np.array([0.3, 0.2, 0.9, 0.5, 0.6, 70, 130, 180, 200, 210, 230, 400.0])
    with pytest.raises(ValueError, match="bands"):
        core.render_background(z(6), z((1, 9)), z((0, 12)), z((0, 10)), z((0, 9)), light,
                               z(6), 8, 8, 90.0, 1)
    with pytest.raises(ValueError, match="tag"):
        core.render_background(z(6), np.array([[0, 1, 300, 0, 0, 0, 0, 0, 0, 0.0]]),
                               z((0, 12)), z((0, 10)), z((0, 9)), light, z(6), 8, 8, 90.0, 1)
    rgb, tags, depth = core.render_background(z(6), z((0, 10)), z((0, 12)), z((0, 10)),
                                              z((0, 9)), light, np.array([0, 0, 1.0, 0, 0, 0]),
                                              8, 6, 90.0, 1)
    assert rgb.shape == (6, 8, 3) and tags.shape == (6, 8) and depth.dtype == np.float32
    assert set(np.unique(tags)) == {0, 13}  # no band: unlabeled ground, sky above
    with pytest.raises(ValueError, match="capsules"):
        core.render_bodies(rgb, tags, depth, z(6), 90.0, light, z((2, 3, 6)), z((3, 3)), 1)


def test_batch_shares_the_street_not_the_walk():
    from bsp_fast.synth import clip

    cfg = make_config("sample", dict(batch_size=2, number_of_clips=3, seed=11))
    a, b, c = (clip.plan_clip(cfg, i) for i in range(3))
    assert a.street == b.street and a.street != c.street
    assert a.id != b.id and not np.array_equal(a.path.sw, b.path.sw)
