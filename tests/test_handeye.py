"""Bindings of the hand-eye estimators (000_3b1454b2b2194811.txt ch. 5): inputs, closed forms, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autoteach import _core
from autoteach.errors import InvalidInputError
from autoteach.geometry import RobotParams
from autoteach.pipeline import _robot_array
from autoteach.sim import simulate_session, true_increments
from autoteach.sim.odometry import integrate_odometry, simulate_odometry

K = np.array([[1000.0, 0.0, 639.5], [0.0, 1000.0, 359.5], [0.0, 0.0, 1.0]])


def _look_along_x(x: float, z: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    t[:3, 3] = (x, 0.0, z)
    return t


def test_resolution_matches_the_pinhole_closed_form():
    # A level wafer 0.6 m ahead at camera height: a 1 mm lateral (y) shift moves every rim point by
    # f/Z px horizontally; its RMS over the rim is f·sqrt(mean(1/Z²)).
    t = _look_along_x(-0.6, 0.0)
    w = np.zeros(5)
    r = _core.handeye_resolution(K, t, w, 0.15, 0.0, n=3600)
    th = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
    z = 0.6 + 0.15 * np.cos(th)
    u = 0.15 * np.sin(th)
    # d(u_px)/dy = f/Z; d(v_px)/dy = 0 (point in the camera's horizontal plane through the centre)
    expect = 1000.0 * np.sqrt(np.mean(1.0 / z**2)) * 1e-3
    assert r[1] == pytest.approx(expect, rel=1e-6)
    # d/dx (along the optical axis) moves points by f·u/Z²
    expect_x = 1000.0 * np.sqrt(np.mean((u / z**2) ** 2)) * 1e-3
    assert r[0] == pytest.approx(expect_x, rel=1e-6)


def test_ukf_with_exact_odometry_recovers_the_offsets():
    s = simulate_session(seed=7, frames=120, render=False)
    inc = true_increments(s.camera_poses)
    d = math.radians
    noise = [1e-5] * 3 + [d(0.001)] * 3 + [1e-5] * 3 + [d(0.001)] * 3 + [d(0.002)] * 3 + [1e-5]
    run = _core.handeye_ukf(_robot_array(s.config.robot), np.array(s.config.base_pose), s.joints_encoder, inc, noise)
    true = s.calibration.joint_offsets[[0, 1, 3]]
    err = np.abs(run["offsets"][-1] - true)
    assert np.all(err < math.radians(0.05)), np.degrees(err)
    assert np.all(err < 3 * run["offset_std"][-1]), (np.degrees(err), np.degrees(run["offset_std"][-1]))
    # the first frame cannot tell the offsets from the pose: the prior (2°) is kept
    assert np.all(run["offset_std"][0] > math.radians(1.0))


def test_odometry_round_trip_and_drift():
    s = simulate_session(seed=2, frames=30, render=False)
    exact = integrate_odometry(s.camera_poses[0], true_increments(s.camera_poses))
    np.testing.assert_allclose(exact, s.camera_poses, atol=1e-9)
    drift = integrate_odometry(s.camera_poses[0], simulate_odometry(s.camera_poses, 2))
    err = np.linalg.norm(drift[:, :3, 3] - s.camera_poses[:, :3, 3], axis=1)
    assert err[-1] > err[3] > 0.0


def test_slam_mot_point_sigma_scale_is_validated_and_used():
    s = simulate_session(seed=1, frames=12, render=False)
    from autoteach.pipeline import _pinhole_k, simulated_frontend

    obs = simulated_frontend(s, seed=1)
    inputs = (
        _pinhole_k(s.camera),
        _robot_array(s.config.robot),
        s.config.wafer_radius,
        s.config.wafer_thickness,
        np.ascontiguousarray(s.joints_encoder),
        len(s.wafer_slots),
    )
    start = (
        np.linalg.inv(np.asarray(s.wafer_poses[0])) @ np.array(s.config.base_pose),
        np.zeros(5),
        np.array([[0, 0, (sl - s.wafer_slots[0]) * s.config.slot_pitch, 0, 0] for sl in s.wafer_slots], float),
    )

    def solve(pixel_sigma: float, scale: np.ndarray | None, **options: object) -> dict:
        flat = (obs.frames, obs.wafers, obs.rims, obs.start, np.ascontiguousarray(obs.points), scale)
        return _core.HandeyeSlamMot(*inputs, pixel_sigma=pixel_sigma, **options).solve(flat, start)

    n = len(obs.points)
    for bad in (np.ones(n + 1), np.zeros(n), np.full(n, np.nan)):
        with pytest.raises(InvalidInputError, match="point_sigma_scale"):
            solve(0.3, bad)
    # A uniform factor 2 is the same problem as a pixel σ twice as large: same estimate, same
    # covariance; any other factor changes the covariance.
    a = solve(0.3, np.full(n, 2.0), huber=None)
    b = solve(0.6, None, huber=None)
    np.testing.assert_allclose(a["base_pose"], b["base_pose"], atol=1e-9)
    np.testing.assert_allclose(a["covariance"], b["covariance"], rtol=1e-6, atol=1e-18)
    c = solve(0.6, np.full(n, 1.5), huber=None)
    assert c["covariance"][3, 3] > 2.0 * b["covariance"][3, 3]


def test_slam_mot_rejects_inconsistent_observations():
    p = _robot_array(RobotParams())
    enc = np.zeros((3, 5))
    slam = _core.HandeyeSlamMot(K, p, 0.15, 0.001, enc, 1)
    start = (np.eye(4), np.zeros(5), np.zeros((1, 5)))
    one = ([0], [0], [0], [0, 4], np.ones((4, 2)), None)
    with pytest.raises(InvalidInputError, match="start"):
        slam.solve(([0], [0], [0], [0], np.zeros((4, 2)), None), start)
    with pytest.raises(InvalidInputError, match="no wafer edge"):
        slam.solve(([], [], [], [0], np.zeros((0, 2)), None), start)
    with pytest.raises(InvalidInputError, match="factor"):
        slam.solve(one, start, factor="x")
    with pytest.raises(InvalidInputError, match="encoders"):
        _core.HandeyeSlamMot(K, p, 0.15, 0.001, np.zeros((3, 4)), 1)
    with pytest.raises(InvalidInputError, match="gates_px"):
        slam.gate_and_resolve(one, start, (np.ones((4, 2)), [0, 4], [0]), gates_px=[], first_heights=(0, 0.1, 0.01))


def test_ukf_rejects_bad_lengths():
    p = _robot_array(RobotParams())
    with pytest.raises(InvalidInputError, match="increments"):
        _core.handeye_ukf(p, np.eye(4), np.zeros((5, 5)), np.zeros((3, 6)))
    with pytest.raises(InvalidInputError, match="noise"):
        _core.handeye_ukf(p, np.eye(4), np.zeros((2, 5)), np.zeros((1, 6)), [1.0] * 3)


def test_relative_odometry_is_the_relative_camera_motion():
    # Independent truth: exact increments of a trajectory turn back into T_wc(t)⁻¹·T_wc(t+1).
    from autoteach.sim import relative_odometry

    s = simulate_session(seed=4, frames=25, render=False)
    t = s.camera_poses
    rel = relative_odometry(true_increments(t), t[0][:3, :3])
    for i in range(len(rel)):
        np.testing.assert_allclose(rel[i], np.linalg.inv(t[i]) @ t[i + 1], atol=1e-12)
    with pytest.raises(InvalidInputError, match="start_rotation"):
        relative_odometry(true_increments(t), np.eye(3) * 2.0)
    with pytest.raises(InvalidInputError, match=r"\(F-1, 6\)"):
        relative_odometry(np.zeros((3, 5)), np.eye(3))
