"""Motion planning and time-optimal trajectories (issue 30), through the Python API."""

from __future__ import annotations

import numpy as np
import pytest

from autoteach import plan
from autoteach.errors import AutoteachError


@pytest.fixture(scope="module")
def scene():
    return plan.default_scene()


def test_default_poses_are_free_and_clearance_names_the_pair(scene):
    ws, poses = scene
    for name, q in poses.items():
        d, link, obstacle = plan.clearance(ws, q)
        assert d > 0.005, name
        assert isinstance(link, str) and isinstance(obstacle, str)


def test_rrt_path_and_optimised_trajectory_verified_by_dense_sampling(scene):
    ws, poses = scene
    p = plan.plan_path(ws, poses["home"], poses["chamber"], method="rrt*", margin=0.02)
    np.testing.assert_array_equal(p.path[0], poses["home"])
    np.testing.assert_array_equal(p.path[-1], poses["chamber"])
    limits = plan.Limits()
    r = plan.optimize_trajectory(ws, p.path, limits)
    assert r.duration <= r.initial_duration
    assert r.duration >= r.lower_bound * (1 - 1e-9)
    # Independent check in Python: sample every 1 ms, limits within 1e-9 relative, clearance.
    t = np.arange(0.0, r.duration, 1e-3)
    q, dq, ddq, dddq = r.trajectory.sample(t)
    assert np.all(np.abs(dq) <= np.asarray(limits.velocity) * (1 + 1e-9))
    assert np.all(np.abs(ddq) <= np.asarray(limits.acceleration) * (1 + 1e-9))
    assert np.all(np.abs(dddq) <= np.asarray(limits.jerk) * (1 + 1e-9))
    clear = min(plan.clearance(ws, qi)[0] for qi in q[::5])
    assert clear >= limits.d_safe
    tau = np.array(
        [plan.inverse_dynamics(qi, dqi, ddqi) for qi, dqi, ddqi in zip(q[::5], dq[::5], ddq[::5], strict=True)]
    )
    assert np.all(np.abs(tau) <= np.asarray(limits.torque) * (1 + 1e-9))


def test_trajectory_save_load_roundtrip(scene, tmp_path):
    ws, poses = scene
    r = plan.optimize_trajectory(ws, np.array([poses["home"], poses["home"] + [0.2, -0.1, 0.1, 0.0, 0.01]]))
    f = tmp_path / "t.json"
    r.trajectory.save(f)
    back = plan.BSplineTrajectory.load(f)
    np.testing.assert_array_equal(back.knots, r.trajectory.knots)
    np.testing.assert_allclose(back.sample(0.3 * r.duration)[0], r.trajectory.sample(0.3 * r.duration)[0])


def test_bad_inputs_raise_clear_errors(scene):
    ws, poses = scene
    bad = poses["carrier_a"] + np.array([0.0, -0.4, 0.2, 0.0, 0.0])
    assert plan.clearance(ws, bad)[0] < 0
    with pytest.raises(AutoteachError, match="goal configuration is not free"):
        plan.plan_path(ws, poses["home"], bad)
    with pytest.raises(AutoteachError, match="torque joint 4"):
        plan.optimize_trajectory(ws, np.array([poses["home"], poses["chamber"]]), plan.Limits(torque=(1, 1, 1, 1, 10)))
    with pytest.raises(AutoteachError, match="shape"):
        plan.clearance(ws, [0.0, 1.0])
    with pytest.raises(AutoteachError, match="must be finite|non-finite"):
        plan.clearance(ws, [np.nan, 0, 0, 0, 0])
    with pytest.raises(AutoteachError, match="unknown method"):
        plan.plan_path(ws, poses["home"], poses["chamber"], method="prm")


def test_free_waypoint_velocities_beat_zero_velocities_and_keep_the_limits():
    # Seed 000 Table 2.2 on a free-space straight move split by two way-points: stopping at
    # them costs two decelerations that free way-point velocities avoid.
    ws = plan.Workspace([])
    w = [np.array([0.6 * k, 0.5 - 0.05 * k, -0.1 * k, 0.1 * k, 0.1]) for k in range(4)]
    paths = [np.stack([w[k], w[k + 1]]) for k in range(3)]
    lim = plan.Limits()
    zero = plan.optimize_waypoints(ws, paths, lim, free_velocities=False)
    free = plan.optimize_waypoints(ws, paths, lim, free_velocities=True)
    assert np.all(zero.velocities == 0.0)
    assert free.duration <= zero.duration
    assert np.linalg.norm(free.velocities) > 0.1
    # Dense 1 ms samples of every segment against the limits, independent of the optimiser.
    for seg in free.segments:
        t = np.arange(0.0, seg.duration, 1e-3)
        _, dq, ddq, dddq = seg.sample(t)
        for x, bound in ((dq, lim.velocity), (ddq, lim.acceleration), (dddq, lim.jerk)):
            assert np.all(np.abs(x) <= np.asarray(bound) * (1.0 + 1e-9))
    # The segments join at the way-points with the reported velocity and zero acceleration.
    for k in range(2):
        a, b = free.segments[k], free.segments[k + 1]
        qa, dqa, ddqa, _ = a.sample(a.duration)
        qb, dqb, ddqb, _ = b.sample(0.0)
        np.testing.assert_allclose(qa[0], w[k + 1], atol=1e-9)
        np.testing.assert_allclose(qb[0], w[k + 1], atol=1e-9)
        np.testing.assert_allclose(dqa[0], free.velocities[k], atol=1e-9)
        np.testing.assert_allclose(dqb[0], free.velocities[k], atol=1e-9)
        assert np.abs(ddqa).max() < 1e-6 and np.abs(ddqb).max() < 1e-6
    assert sum(s.duration for s in free.segments) == pytest.approx(free.duration, rel=1e-9)
    paths[1] = paths[1] + 1e-3
    with pytest.raises(AutoteachError, match="segment 0 ends"):
        plan.optimize_waypoints(ws, paths, lim)
