"""Tests of the simulated robot session (autoteach.sim)."""

from __future__ import annotations

import dataclasses
import json
import math

import cv2
import numpy as np
import pytest

from autoteach.errors import InvalidInputError
from autoteach.geometry import Camera, RobotParams, WaferRobot, joints_from_encoders, project_circle
from autoteach.sim import BSpline, Lighting, SimConfig, TrajectoryConfig, simulate_session, wafer_poses
from autoteach.sim.simulate import camera_target_pose, plan_joint_waypoints

# A quarter-resolution camera with the default field of view keeps the tests fast.
SMALL = SimConfig(camera_params=(250.0, 250.0, 159.5, 89.5), width=320, height=180, supersample=2)


def pinhole_k(session):
    fx, fy, cx, cy = session.camera.params
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def session():
    return simulate_session(seed=5, frames=6, config=SMALL)


@pytest.fixture(scope="module")
def long_session():
    """Many frames without images: trajectory, encoders and rim ground truth only."""
    return simulate_session(seed=9, frames=120, config=SMALL, render=False)


# --- determinism -------------------------------------------------------------------------------


def test_same_seed_gives_identical_session(session):
    again = simulate_session(seed=5, frames=6, config=SMALL)
    assert np.array_equal(again.images, session.images)
    assert np.array_equal(again.joints_encoder, session.joints_encoder)
    assert np.array_equal(again.joints_true, session.joints_true)
    assert np.array_equal(again.wafer_poses, session.wafer_poses)
    assert np.array_equal(again.timestamps, session.timestamps)


def test_different_seed_differs(session):
    other = simulate_session(seed=6, frames=6, config=SMALL)
    assert not np.array_equal(other.images, session.images)
    assert not np.array_equal(other.joints_true, session.joints_true)
    assert not np.array_equal(other.calibration.joint_offsets, session.calibration.joint_offsets)


def test_scene_does_not_depend_on_frame_count(session):
    shorter = simulate_session(seed=5, frames=2, config=SMALL, render=False)
    assert np.array_equal(shorter.wafer_poses, session.wafer_poses)
    assert np.array_equal(shorter.calibration.joint_offsets, session.calibration.joint_offsets)


# --- shapes and defaults -----------------------------------------------------------------------


def test_session_shapes_and_timestamps(session):
    f = 6
    assert session.images.shape == (f, 180, 320) and session.images.dtype == np.uint8
    assert session.joints_true.shape == (f, 5) and session.joints_encoder.shape == (f, 5)
    assert session.camera_poses.shape == (f, 4, 4)
    assert session.wafer_poses.shape == (12, 4, 4)
    assert session.wafer_slots.tolist() == [4, 7, 10, 13, 15, 17, 19, 21, 22, 23, 24, 25]
    assert np.array_equal(session.timestamps, np.arange(f) * 100_000_000)  # 10 Hz
    assert len(session.rims) == f
    assert session.images.std() > 5.0  # not blank


def test_default_wafer_poses_follow_the_slots():
    cfg = SimConfig(placement_tilt_sigma=0.0, placement_shift_sigma=0.0, shifts={7: (0.001, -0.0005, 0.0)})
    poses = wafer_poses(cfg, np.random.default_rng(0))
    for pose, slot in zip(poses, cfg.slots, strict=True):
        expected_z = (slot - 1) * 0.010
        assert pose[2, 3] == pytest.approx(expected_z, abs=1e-15)
        assert np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-15)
    # slot 25 is tilted by 1 degree (about y), the others are level
    tilt = np.degrees(np.arccos(poses[:, 2, 2]))
    assert tilt[-1] == pytest.approx(1.0, abs=1e-9)
    assert np.all(tilt[:-1] < 1e-6)
    assert poses[1, :2, 3] == pytest.approx([0.001, -0.0005], abs=1e-15)


def test_default_joint_offsets_are_in_range(session):
    off = session.calibration.joint_offsets
    assert np.all(np.abs(np.degrees(off[:4])) >= 0.2) and np.all(np.abs(np.degrees(off[:4])) <= 1.0)
    assert off[4] == 0.0


def test_configured_joint_offsets_are_used():
    offsets = (0.01, -0.004, 0.002, -0.015, 0.0003)
    s = simulate_session(seed=1, frames=2, config=SMALL.with_(joint_offsets=offsets), render=False)
    assert s.calibration.joint_offsets.tolist() == list(offsets)


# --- encoder model -----------------------------------------------------------------------------


def test_encoders_carry_offsets_and_noise(long_session):
    s = long_session
    noise = np.asarray(SMALL.encoder_noise)
    recovered = joints_from_encoders(s.joints_encoder, s.calibration.joint_offsets)
    residual = recovered - s.joints_true
    assert np.all(np.abs(residual) < 6.0 * noise)
    # the residual is white noise of the configured std (120 samples: within 25 %)
    assert np.allclose(residual.std(axis=0), noise, rtol=0.25)
    # and the raw readings really are offset
    assert np.allclose((s.joints_encoder - s.joints_true).mean(axis=0), s.calibration.joint_offsets, atol=3 * noise)


# --- ground-truth consistency ------------------------------------------------------------------


def test_camera_poses_follow_forward_kinematics(session):
    cal = session.calibration
    robot = WaferRobot(cal.robot_params, cal.base_pose)
    assert np.allclose(robot.camera_pose(session.joints_true), session.camera_poses, atol=1e-12)
    # T_wc = T_wb · T_be2 · T_e2c (eq. (2.2)) with the stored mount
    chain = cal.base_pose @ robot.blade_pose(session.joints_true, 2) @ cal.camera_mount
    assert np.allclose(chain, session.camera_poses, atol=1e-12)


def test_rim_ellipses_match_project_circle(session):
    k = pinhole_k(session)
    checked = 0
    for frame, t_wc in zip(session.rims, session.camera_poses, strict=True):
        t_cw = np.linalg.inv(t_wc)
        for rim in frame:
            if rim["ellipse"] is None:
                continue
            pose = session.wafer_poses[rim["wafer"]]
            sign = 1.0 if rim["rim"] == "upper" else -1.0
            centre = pose[:3, 3] + sign * 0.0005 * pose[:3, 2]
            e = project_circle(k, t_cw, centre, pose[:3, 2], 0.150)
            got = rim["ellipse"]
            assert got[:4] == pytest.approx([e.cx, e.cy, e.a, e.b], rel=1e-9, abs=1e-9)
            # the orientation is defined modulo π (irrelevant for circles, a == b)
            dtheta = (got[4] - e.theta + np.pi / 2) % np.pi - np.pi / 2
            assert abs(dtheta) < 1e-7 or abs(e.a - e.b) < 1e-6
            checked += 1
    assert checked > 50


def test_rim_points_match_opencv_projection(session):
    """Visible rim samples are the projections of the rim circle at their angles (OpenCV peer)."""
    k = pinhole_k(session)
    for frame, t_wc in zip(session.rims[:2], session.camera_poses[:2], strict=True):
        t_cw = np.linalg.inv(t_wc)
        rvec, _ = cv2.Rodrigues(t_cw[:3, :3])
        for rim in frame:
            if len(rim["angles"]) == 0:
                continue
            pose = session.wafer_poses[rim["wafer"]]
            z = 0.0005 if rim["rim"] == "upper" else -0.0005
            a = rim["angles"]
            local = np.stack([0.15 * np.cos(a), 0.15 * np.sin(a), np.full_like(a, z), np.ones_like(a)])
            world = (pose @ local)[:3].T
            px, _ = cv2.projectPoints(world, rvec, t_cw[:3, 3], k, None)
            assert np.allclose(px.reshape(-1, 2), rim["points"], atol=1e-6)
            assert 0.0 <= rim["fraction"] <= 1.0
            # the intervals' total length is the visible fraction
            iv = rim["intervals"]
            assert (iv[:, 1] - iv[:, 0]).sum() / (2 * np.pi) == pytest.approx(rim["fraction"], abs=1e-12)


def test_rims_are_drawn_where_the_ground_truth_says(session):
    """The image has a strong edge at the visible, side-facing rim samples."""
    for img, frame in zip(session.images, session.rims, strict=True):
        g = img.astype(np.float64)
        gx = cv2.Sobel(g, cv2.CV_64F, 1, 0, ksize=3)
        gy = cv2.Sobel(g, cv2.CV_64F, 0, 1, ksize=3)
        mag = np.hypot(gx, gy)
        # max over a 3x3 neighbourhood: the rim is a thin bright band, the sample may sit on its centre
        mag = cv2.dilate(mag, np.ones((3, 3)))
        pts = np.concatenate([r["points"][r["side_facing"]] for r in frame])
        ij = np.round(pts).astype(int)
        inside = (ij[:, 0] >= 1) & (ij[:, 0] < img.shape[1] - 1) & (ij[:, 1] >= 1) & (ij[:, 1] < img.shape[0] - 1)
        at_rims = mag[ij[inside, 1], ij[inside, 0]]
        assert len(at_rims) > 100
        # the carrier's slot ridges make this small image busy with edges; the rims still stand out
        assert np.median(at_rims) > 3.0 * np.median(mag)
        assert np.median(at_rims) > 100.0


def test_every_wafer_is_seen(long_session):
    stats = long_session.wafer_visibility()
    assert [v["slot"] for v in stats] == list(SMALL.slots)
    for v in stats:
        assert v["frames_visible"] >= 0.3 * long_session.n_frames, v


def test_wafers_leave_and_reenter_view(long_session):
    """The sweep takes the top wafers out of view and back (tracking needs this)."""
    top = len(SMALL.slots) - 1
    seen = np.array([any(r["wafer"] == top and r["fraction"] > 0 for r in f) for f in long_session.rims])
    assert seen[0] and seen[-1] and not seen.all()


# --- trajectory --------------------------------------------------------------------------------


def test_joint_trajectory_is_smooth(long_session):
    q = long_session.joints_true
    v = np.diff(q, axis=0)
    acc = np.diff(v, axis=0)
    # C2 spline sampled finely: accelerations change little from frame to frame
    assert np.abs(np.diff(acc, axis=0)).max() < 0.1 * np.abs(v).max()
    assert np.abs(v[:, :4]).max() < 0.2  # rad per frame


def test_explicit_waypoints_are_reached():
    wps = ((-0.50, 0.02, 0.20, math.radians(3.0)), (-0.45, -0.03, 0.10, 0.0), (-0.42, 0.0, 0.15, -0.05))
    cfg = SMALL.with_(trajectory=TrajectoryConfig(waypoints=wps))
    s = simulate_session(seed=0, frames=7, config=cfg, render=False)
    for frame, wp in ((0, wps[0]), (-1, wps[-1])):  # the clamped spline starts and ends at its ends
        t = s.camera_poses[frame]
        assert t[:3, 3] == pytest.approx(wp[:3], abs=1e-9)
        axis = t[:3, 2]
        assert math.atan2(axis[1], axis[0]) == pytest.approx(wp[3], abs=1e-9)
        assert math.degrees(math.asin(-axis[2])) == pytest.approx(8.0, abs=1e-9)  # beta_c, looking down


def test_single_waypoint_is_a_static_camera():
    cfg = SMALL.with_(trajectory=TrajectoryConfig(waypoints=((-0.45, 0.0, 0.12, 0.0),)))
    s = simulate_session(seed=0, frames=4, config=cfg, render=False)
    assert np.all(s.joints_true == s.joints_true[0])


def test_ik_planning_recovers_the_target_pose():
    robot = WaferRobot(RobotParams(), SimConfig().base_pose_matrix)
    wps = np.array([[-0.5, 0.05, 0.1, 0.02], [-0.41, -0.07, 0.25, -0.08]])
    q = plan_joint_waypoints(robot, wps)
    for qi, wp in zip(q, wps, strict=True):
        target = camera_target_pose(robot, *wp)
        assert np.allclose(robot.camera_pose(qi), target, atol=1e-12)
    assert q[0, 1] > 0  # elbow sign +1 by default


def test_unreachable_waypoint_is_reported():
    from autoteach.errors import UnreachablePoseError

    cfg = SMALL.with_(trajectory=TrajectoryConfig(waypoints=((-3.0, 0.0, 0.1, 0.0),)))
    with pytest.raises(UnreachablePoseError, match="waypoint 0"):
        simulate_session(seed=0, frames=2, config=cfg, render=False)


def test_bspline_matches_scipy_and_is_clamped():
    scipy_interpolate = pytest.importorskip("scipy.interpolate")
    rng = np.random.default_rng(3)
    p = rng.normal(size=(7, 3))
    ours = BSpline(p, 0.0, 2.0)
    ref = scipy_interpolate.BSpline(ours.knots, p, 3)
    t = np.linspace(0.0, 2.0, 101)
    assert np.allclose(ours(t), ref(t), atol=1e-12)
    assert np.allclose(ours.derivative()(t), ref.derivative()(t), atol=1e-10)
    assert np.allclose(ours(0.0), p[0]) and np.allclose(ours(2.0), p[-1])  # eq. (2.15)
    # B'(0) = 3 (P2 − P1) / (t5 − t1), eq. (2.15)
    assert np.allclose(ours.derivative()(0.0), 3 * (p[1] - p[0]) / (ours.knots[4] - ours.knots[0]))
    assert np.allclose(ours.basis(t).sum(axis=1), 1.0)  # partition of unity


def test_bspline_with_few_points_lowers_its_degree():
    s = BSpline(np.array([[0.0], [2.0]]))
    assert s.degree == 1
    assert s(0.25) == pytest.approx([0.5])


# --- lighting ----------------------------------------------------------------------------------


def test_lighting_schedule_stays_in_range_and_keyframes_interpolate():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 30, 301)
    gain, grad = Lighting().schedule(t, rng)
    assert gain.min() >= 0.8 - 1e-12 and gain.max() <= 1.2 + 1e-12 and gain.std() > 0.02
    assert np.abs(grad).max() <= 0.2 + 1e-12
    keyed = Lighting(keyframes=((0.0, 1.0, 0.0, 0.0), (2.0, 0.6, 0.2, -0.1)))
    gain, grad = keyed.schedule(np.array([-1.0, 1.0, 5.0]), rng)
    assert gain.tolist() == pytest.approx([1.0, 0.8, 0.6])
    assert grad[1].tolist() == pytest.approx([0.1, -0.05])


def test_lighting_changes_the_image_brightness():
    dark = SMALL.with_(lighting=Lighting(keyframes=((0.0, 0.6, 0.0, 0.0),)), noise_sigma=0.0)
    bright = SMALL.with_(lighting=Lighting(keyframes=((0.0, 1.2, 0.0, 0.0),)), noise_sigma=0.0)
    a = simulate_session(seed=2, frames=1, config=dark).images[0].astype(float)
    b = simulate_session(seed=2, frames=1, config=bright).images[0].astype(float)
    assert b.mean() / a.mean() == pytest.approx(2.0, rel=0.05)


# --- configuration -----------------------------------------------------------------------------


def test_default_tilt_only_when_slot_25_is_occupied():
    assert SimConfig().tilts == {25: (0.0, math.radians(1.0))}
    assert SimConfig(slots=(5, 7)).tilts == {}
    assert SimConfig(slots=(5, 25), tilts={5: (0.01, 0.0)}).tilts == {5: (0.01, 0.0)}


def test_config_round_trips_through_json():
    cfg = SimConfig(
        slots=(5, 6, 20),
        tilts={6: (0.01, -0.02)},
        shifts={20: (0.001, 0.0, -0.0002)},
        joint_offsets=(0.01, 0.02, -0.003, 0.004, 0.0),
        lighting=Lighting(keyframes=((0.0, 1.0, 0.1, 0.0), (1.0, 0.7, 0.0, 0.2))),
        trajectory=TrajectoryConfig(n_waypoints=5, z_range=(0.05, 0.2)),
        robot=dataclasses.replace(RobotParams(), l1=0.361),
    )
    again = SimConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert again == cfg
    assert hash(again) == hash(cfg)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"slots": (4, 27)}, "do not exist"),
        ({"slots": (0,)}, "do not exist"),
        ({"slots": (4, 4)}, "unique"),
        ({"slots": ()}, "at least one"),
        ({"tilts": {9: (0.0, 0.01)}}, "hold no wafer"),
        ({"wafer_radius": float("nan")}, "wafer_radius"),
        ({"slot_pitch": -0.01}, "slot_pitch"),
        ({"encoder_noise": (1e-5, 1e-5, float("nan"), 1e-5, 1e-6)}, "finite"),
        ({"camera_params": (1000.0, float("inf"), 639.5, 359.5)}, "finite"),
        ({"width": 0}, "width"),
        ({"camera_model": "fisheye"}, "kannala_brandt"),
        ({"camera_model": "nope"}, "unknown camera model"),
        ({"camera_params": (1000.0, 1000.0, 639.5)}, "param"),
        ({"frame_rate_hz": 0.0}, "frame_rate_hz"),
        ({"base_pose": np.eye(4) * 2}, "rigid"),
        ({"joint_offsets": (0.1, 0.2)}, "5 values"),
    ],
)
def test_bad_config_is_rejected(changes, match):
    with pytest.raises(InvalidInputError, match=match):
        SimConfig(**changes)


def test_bad_lighting_and_trajectory_are_rejected():
    with pytest.raises(InvalidInputError, match="positive"):
        Lighting(gain_range=(0.0, 1.0))
    with pytest.raises(InvalidInputError, match="increasing"):
        Lighting(keyframes=((1.0, 1.0, 0.0, 0.0), (0.5, 1.0, 0.0, 0.0)))
    with pytest.raises(InvalidInputError, match="low <= high"):
        TrajectoryConfig(x_range=(-0.4, -0.5))
    with pytest.raises(InvalidInputError, match="n_waypoints"):
        TrajectoryConfig(n_waypoints=0)
    with pytest.raises(InvalidInputError, match="4 values"):
        TrajectoryConfig(waypoints=((0.0, 0.0, 0.0),))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frames": 0}, "frames"),
        ({"frames": -3}, "frames"),
        ({"frames": 2.5}, "frames"),
        ({"seed": -1}, "seed"),
        ({"config": {"slots": (4,)}}, "SimConfig"),
    ],
)
def test_bad_arguments_are_rejected(kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        simulate_session(**kwargs)


def test_other_carrier_layouts_need_carrier_off():
    with pytest.raises(InvalidInputError, match="26 slots"):
        simulate_session(frames=1, config=SMALL.with_(n_slots=30))
    s = simulate_session(frames=1, config=SMALL.with_(n_slots=30, slots=(28,), tilts={}, carrier=False), render=False)
    assert s.wafer_poses[0, 2, 3] == pytest.approx(0.27)


def test_summary_is_json(session):
    summary = json.loads(json.dumps(session.summary()))
    assert summary["frames"] == 6 and summary["wafers"] == 12
    assert len(summary["calibration"]["joint_offsets_deg"]) == 4
    assert len(summary["visibility"]) == 12


def test_camera_info_builds_a_geometry_camera(session):
    cam = session.camera.to_camera()
    assert isinstance(cam, Camera)
    assert np.allclose(cam.K, [[250, 0, 159.5], [0, 250, 89.5], [0, 0, 1]])


def test_disturbance_scenario_configures_easily():
    """Target wafer in slot 5, a disturbance wafer 7 slots above, static camera, light dimming (seed ch. 3.5)."""
    cfg = SMALL.with_(
        slots=(5, 12),
        tilts={},
        trajectory=TrajectoryConfig(waypoints=((-0.45, 0.0, 0.09, 0.0),)),
        lighting=Lighting(keyframes=((0.0, 1.2, 0.0, 0.0), (0.3, 0.7, 0.1, 0.0))),
        noise_sigma=0.0,
    )
    s = simulate_session(seed=0, frames=4, config=cfg)
    assert np.all(s.camera_poses == s.camera_poses[0])
    target = [max(r["fraction"] for r in f if r["wafer"] == 0) for f in s.rims]
    assert min(target) > 0.2
    brightness = s.images.reshape(4, -1).mean(axis=1)
    assert np.all(np.diff(brightness) < 0)  # the light dims frame by frame
