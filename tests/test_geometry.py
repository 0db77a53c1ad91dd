"""Tests of autoteach.geometry: the Python face of the geometry crate.

Truth comes from independent sources: OpenCV (projection, Rodrigues), closed forms written
out here in NumPy (robot forward kinematics, conic of an ellipse), finite differences
(Jacobians, accelerations) and round trips (exp/log, IK/FK, project/unproject, conic).
"""

from __future__ import annotations

import math
import pickle
import threading
import time

import cv2
import numpy as np
import pytest

from autoteach import _core
from autoteach import geometry as g
from autoteach.errors import (
    AutoteachError,
    DegenerateGeometryError,
    InvalidInputError,
    UnreachablePoseError,
)

RNG_SEED = 20240611


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(RNG_SEED)


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector, by OpenCV (an independent implementation)."""
    return cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0]


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def homogeneous(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def random_pose(rng: np.random.Generator, angle: float = math.pi, dist: float = 1.0) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return homogeneous(rodrigues(axis * rng.uniform(0, angle)), rng.uniform(-dist, dist, size=3))


def wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


# ------------------------------------------------------------------------------------------
# Lie groups, quaternions, Euler angles
# ------------------------------------------------------------------------------------------


class TestLie:
    def test_so3_exp_matches_opencv_rodrigues(self, rng):
        omega = rng.normal(size=(50, 3)) * rng.uniform(0, 3, size=(50, 1))
        R = g.so3_exp(omega)
        assert R.shape == (50, 3, 3)
        for w, r in zip(omega, R, strict=True):
            np.testing.assert_allclose(r, rodrigues(w), atol=1e-13)

    def test_so3_log_inverts_exp(self, rng):
        axis = rng.normal(size=(40, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        omega = axis * rng.uniform(0, math.pi - 1e-3, size=(40, 1))
        omega[0] = 0.0  # identity
        omega[1] = [1e-9, -2e-9, 3e-9]  # tiny angle
        np.testing.assert_allclose(g.so3_log(g.so3_exp(omega)), omega, atol=1e-12)
        # And OpenCV agrees on the logarithm.
        R = rodrigues(omega[5])
        np.testing.assert_allclose(g.so3_log(R), cv2.Rodrigues(R)[0].ravel(), atol=1e-12)

    def test_se3_exp_log_round_trip_and_batch_shapes(self, rng):
        xi = rng.normal(size=(3, 4, 6)) * 0.7
        T = g.se3_exp(xi)
        assert T.shape == (3, 4, 4, 4)
        np.testing.assert_allclose(T[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], (3, 4, 4)), atol=0)
        # Rotation block is Exp(ω): rotation first in ξ = [ω; ρ].
        np.testing.assert_allclose(T[..., :3, :3], g.so3_exp(xi[..., :3]), atol=1e-13)
        np.testing.assert_allclose(g.se3_log(T), xi, atol=1e-12)
        # A single item keeps no batch dimension.
        assert g.se3_exp(xi[0, 0]).shape == (4, 4)
        assert g.se3_log(T[0, 0]).shape == (6,)

    def test_se3_exp_of_pure_translation(self):
        T = g.se3_exp([0, 0, 0, 1.0, -2.0, 3.0])
        np.testing.assert_allclose(T, homogeneous(np.eye(3), [1.0, -2.0, 3.0]), atol=0)

    def test_se3_plus_is_right_perturbation_and_minus_inverts_it(self, rng):
        X = np.stack([random_pose(rng) for _ in range(6)])
        d = rng.normal(size=(6, 6)) * 0.5
        Y = g.se3_plus(X, d)
        np.testing.assert_allclose(Y, X @ g.se3_exp(d), atol=1e-12)
        np.testing.assert_allclose(g.se3_minus(Y, X), d, atol=1e-10)
        # Y ⊖ X = Log(X⁻¹ Y).
        np.testing.assert_allclose(g.se3_minus(Y, X), g.se3_log(np.linalg.inv(X) @ Y), atol=1e-10)

    def test_se3_plus_broadcasts_leading_dimensions(self, rng):
        X = random_pose(rng)
        d = rng.normal(size=(5, 6)) * 0.3
        Y = g.se3_plus(X, d)
        assert Y.shape == (5, 4, 4)
        np.testing.assert_allclose(Y[2], g.se3_plus(X, d[2]), atol=1e-14)
        assert g.se3_minus(Y, X).shape == (5, 6)
        with pytest.raises(InvalidInputError, match="do not broadcast"):
            g.se3_plus(np.stack([X, X, X]), d)

    def test_quaternions(self, rng):
        axis = rng.normal(size=(20, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        angle = rng.uniform(0, math.pi, size=20)
        q = np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis], axis=1)
        R = g.quat_to_matrix(q)
        for ri, a, n in zip(R, angle, axis, strict=True):
            np.testing.assert_allclose(ri, rodrigues(a * n), atol=1e-13)
        # Unnormalised and negated quaternions describe the same rotation.
        np.testing.assert_allclose(g.quat_to_matrix(-3.0 * q), R, atol=1e-13)
        back = g.matrix_to_quat(R)
        assert back.shape == (20, 4)
        assert np.all(back[:, 0] >= 0)
        np.testing.assert_allclose(back, q * np.sign(q[:, :1]), atol=1e-12)
        with pytest.raises(InvalidInputError, match="quaternion"):
            g.quat_to_matrix([0.0, 0.0, 0.0, 0.0])

    def test_euler_zyx_and_xyz(self, rng):
        ang = rng.uniform([-3, -1.5, -3], [3, 1.5, 3], size=(30, 3))
        R = g.euler_zyx_to_matrix(ang)
        for (yaw, pitch, roll), r in zip(ang, R, strict=True):
            np.testing.assert_allclose(r, rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), atol=1e-14)
        np.testing.assert_allclose(g.matrix_to_euler_zyx(R), ang, atol=1e-12)
        R2 = g.euler_xyz_to_matrix(ang)
        for (a, b, c), r in zip(ang, R2, strict=True):
            np.testing.assert_allclose(r, rot_x(a) @ rot_y(b) @ rot_z(c), atol=1e-14)
        np.testing.assert_allclose(g.matrix_to_euler_xyz(R2), ang, atol=1e-12)

    def test_rotation_inputs_must_be_rotations(self):
        with pytest.raises(InvalidInputError, match="R is not a rotation"):
            g.so3_log(np.diag([1.0, 1.0, -1.0]))
        with pytest.raises(InvalidInputError, match=r"R\[1\]"):
            g.matrix_to_quat(np.stack([np.eye(3), 2 * np.eye(3)]))
        with pytest.raises(InvalidInputError, match="T is not a rigid transform"):
            g.se3_log(np.diag([1.0, 1.0, 1.0, 2.0]))


# ------------------------------------------------------------------------------------------
# The wafer robot
# ------------------------------------------------------------------------------------------

SKEWED = {
    "l1": 0.41,
    "l2": 0.33,
    "l3": 0.29,
    "l4": 0.35,
    "h01": 0.21,
    "h02": 0.27,
    "alpha1": 0.03,
    "alpha2": -0.05,
    "beta_c": 0.2,
    "cam_d": 0.07,
    "cam_h": 0.04,
}


@pytest.fixture
def robot() -> g.WaferRobot:
    base = homogeneous(rot_z(0.7) @ rot_y(0.01) @ rot_x(-0.02), [1.2, -0.4, 0.3])
    return g.WaferRobot(SKEWED, base=base)


def random_joints(rng: np.random.Generator, n: int) -> np.ndarray:
    lo = [-math.pi, -math.pi, -math.pi, -math.pi, -0.2]
    hi = [math.pi, math.pi, math.pi, math.pi, 0.4]
    return rng.uniform(lo, hi, size=(n, 5))


def blade_pose_closed_form(p: dict, q: np.ndarray, blade: int) -> np.ndarray:
    """Seed eq. (2.4) with the blade yaw: translation of the three links, Rz(ψ)·Ry(α)."""
    t1, t2, t3, t4, h = q
    length, height, pitch, wrist = (
        (p["l3"], p["h01"], p["alpha1"], t3) if blade == 1 else (p["l4"], p["h02"], p["alpha2"], t4)
    )
    t12, psi = t1 + t2, t1 + t2 + wrist
    x = p["l1"] * math.cos(t1) + p["l2"] * math.cos(t12) + length * math.cos(psi)
    y = p["l1"] * math.sin(t1) + p["l2"] * math.sin(t12) + length * math.sin(psi)
    return homogeneous(rot_z(psi) @ rot_y(pitch), [x, y, h + height])


class TestRobot:
    def test_params_dataclass_mirrors_rust(self):
        default = g.RobotParams()
        assert g.WaferRobot().params == default
        assert list(default.to_dict()) == [
            "l1",
            "l2",
            "l3",
            "l4",
            "h01",
            "h02",
            "alpha1",
            "alpha2",
            "beta_c",
            "cam_d",
            "cam_h",
        ]
        r = g.WaferRobot({"l1": 0.5})
        assert r.params.l1 == 0.5 and r.params.l2 == default.l2
        r2 = g.WaferRobot(g.RobotParams(**SKEWED))
        assert r2.params.to_dict() == SKEWED
        assert g.RobotParams.from_dict(SKEWED) == g.RobotParams(**SKEWED)
        np.testing.assert_array_equal(g.WaferRobot().base, np.eye(4))

    def test_invalid_params(self):
        with pytest.raises(InvalidInputError, match="unknown robot parameter"):
            g.WaferRobot({"l5": 1.0})
        with pytest.raises(InvalidInputError, match="l2"):
            g.WaferRobot({"l2": -0.1})
        with pytest.raises(InvalidInputError, match="beta_c"):
            g.WaferRobot({"beta_c": 2.0})
        with pytest.raises(InvalidInputError, match="l1"):
            g.WaferRobot({"l1": float("nan")})
        with pytest.raises(InvalidInputError, match="base"):
            g.WaferRobot(base=np.diag([1.0, 2.0, 1.0, 1.0]))
        with pytest.raises(InvalidInputError, match="params"):
            g.WaferRobot([0.3, 0.3])  # type: ignore[arg-type]

    @pytest.mark.parametrize("blade", [1, 2])
    def test_blade_pose_matches_eq_2_4(self, robot, rng, blade):
        qs = random_joints(rng, 25)
        T = robot.blade_pose(qs, blade)
        assert T.shape == (25, 4, 4)
        for q, t in zip(qs, T, strict=True):
            np.testing.assert_allclose(t, blade_pose_closed_form(SKEWED, q, blade), atol=1e-13)

    def test_camera_pose_chain_and_batch_shapes(self, robot, rng):
        qs = random_joints(rng, 24)
        T_wc = robot.camera_pose(qs)
        chain = robot.base @ robot.blade_pose(qs, 2) @ robot.camera_mount()
        np.testing.assert_allclose(T_wc, chain, atol=1e-12)
        in_base = robot.blade_pose(qs, 2) @ robot.camera_mount()
        np.testing.assert_allclose(robot.camera_pose_in_base(qs), in_base, atol=1e-14)
        assert robot.camera_pose(qs[0]).shape == (4, 4)
        assert robot.camera_pose(qs.reshape(2, 3, 4, 5)).shape == (2, 3, 4, 4, 4)
        np.testing.assert_allclose(robot.camera_pose(qs.reshape(4, 6, 5))[1, 2], T_wc[8], atol=0)
        assert robot.camera_pose(np.zeros((0, 5))).shape == (0, 4, 4)

    def test_camera_mount_geometry(self):
        p = g.RobotParams(**SKEWED)
        mount = g.WaferRobot(p).camera_mount()
        # Optical axis along the blade, tilted down by beta_c; image x to the blade's right.
        np.testing.assert_allclose(mount[:3, 2], [math.cos(p.beta_c), 0, -math.sin(p.beta_c)], atol=1e-15)
        np.testing.assert_allclose(mount[:3, 0], [0, -1, 0], atol=1e-15)
        np.testing.assert_allclose(mount[:3, 3], [-p.cam_d, 0, p.cam_h], atol=1e-15)

    def test_large_batch_matches_small_batches(self, robot, rng):
        # 3000 x 16 outputs: beyond the GIL-release threshold of the bindings.
        qs = random_joints(rng, 3000)
        big = robot.camera_pose(qs)
        small = np.concatenate([robot.camera_pose(qs[i : i + 100]) for i in range(0, 3000, 100)])
        np.testing.assert_array_equal(big, small)
        np.testing.assert_allclose(robot.blade_pose(qs, 1)[1234], robot.blade_pose(qs[1234], 1), atol=0)

    @pytest.mark.parametrize("blade", [1, 2])
    def test_jacobian_matches_finite_differences(self, robot, rng, blade):
        eps = 1e-6
        for q in random_joints(rng, 5):
            J = robot.jacobian(q, blade)
            assert J.shape == (4, 5)
            num = np.zeros((4, 5))
            for j in range(5):
                dq = np.zeros(5)
                dq[j] = eps
                Tp, Tm = robot.blade_pose(q + dq, blade), robot.blade_pose(q - dq, blade)
                num[:3, j] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
                # Yaw rate: the blade x axis turns about the base z axis.
                yaw_p, yaw_m = (math.atan2(T[1, 0], T[0, 0]) for T in (Tp, Tm))
                num[3, j] = wrap(yaw_p - yaw_m) / (2 * eps)
            np.testing.assert_allclose(J, num, atol=1e-8)
        assert robot.jacobian(random_joints(rng, 6).reshape(2, 3, 5), blade).shape == (2, 3, 4, 5)

    def test_camera_jacobian_matches_finite_differences(self, robot, rng):
        eps = 1e-6
        for q in random_joints(rng, 5):
            J = robot.camera_jacobian(q)
            assert J.shape == (6, 5)
            dq = np.eye(5) * eps
            Tp, Tm = robot.camera_pose(q + dq), robot.camera_pose(q - dq)
            T0 = robot.camera_pose(q)
            num = (g.se3_minus(Tp, T0) - g.se3_minus(Tm, T0)).T / (2 * eps)
            np.testing.assert_allclose(J, num, atol=1e-8)

    @pytest.mark.parametrize("blade", [1, 2])
    def test_acceleration_matches_second_difference(self, robot, rng, blade):
        h = 1e-4
        for q in random_joints(rng, 4):
            qd, qdd = rng.normal(size=5), rng.normal(size=5)
            acc = robot.acceleration(q, qd, qdd, blade=blade)

            def state(t, q=q, qd=qd, qdd=qdd):
                T = robot.blade_pose(q + qd * t + 0.5 * qdd * t * t, blade)
                return np.array([T[0, 3], T[1, 3], T[2, 3], math.atan2(T[1, 0], T[0, 0])])

            sp, s0, sm = state(h), state(0.0), state(-h)
            num = sp - 2 * s0 + sm
            num[3] = wrap(sp[3] - s0[3]) - wrap(s0[3] - sm[3])
            np.testing.assert_allclose(acc, num / h**2, atol=2e-6)
        # Leading dimensions broadcast.
        qs = random_joints(rng, 3)
        assert robot.acceleration(qs, np.zeros(5), np.ones(5), blade).shape == (3, 4)

    @pytest.mark.parametrize("blade", [1, 2])
    def test_inverse_kinematics_round_trip(self, robot, rng, blade):
        for q in random_joints(rng, 40):
            other = q[3] if blade == 1 else q[2]
            T = robot.blade_pose(q, blade)
            sols = robot.inverse_kinematics(T, blade=blade, other_blade_angle=other)
            assert sols.ndim == 2 and sols.shape[1] == 5 and 1 <= len(sols) <= 2
            for s in sols:
                np.testing.assert_allclose(robot.blade_pose(s, blade), T, atol=1e-10)
            # The joint vector we started from is among the solutions (angles modulo 2π).
            err = np.abs(wrap(sols[:, :4] - q[:4])).max(axis=1) + np.abs(sols[:, 4] - q[4])
            assert err.min() < 1e-9

    def test_inverse_kinematics_camera_round_trip(self, robot, rng):
        for q in random_joints(rng, 20):
            T_wc = robot.camera_pose(q)
            sols = robot.inverse_kinematics_camera(T_wc, theta3=q[2])
            for s in sols:
                np.testing.assert_allclose(robot.camera_pose(s), T_wc, atol=1e-10)
            err = np.abs(wrap(sols[:, :4] - q[:4])).max(axis=1) + np.abs(sols[:, 4] - q[4])
            assert err.min() < 1e-9

    def test_unreachable_pose(self, robot):
        far = homogeneous(rot_z(0.3) @ rot_y(SKEWED["alpha1"]), [5.0, 0.0, 0.3])
        with pytest.raises(UnreachablePoseError, match="outside the reachable annulus") as info:
            robot.inverse_kinematics(far, blade=1)
        assert isinstance(info.value, ValueError) and isinstance(info.value, AutoteachError)
        # The message quotes the numbers: the reach l1 + l2.
        assert f"{SKEWED['l1'] + SKEWED['l2']:.6f}" in str(info.value)
        tilted = homogeneous(rot_x(0.2), [0.5, 0.0, 0.3])
        with pytest.raises(UnreachablePoseError, match="roll"):
            robot.inverse_kinematics(tilted, blade=1)
        with pytest.raises(UnreachablePoseError):
            robot.inverse_kinematics_camera(homogeneous(np.eye(3), [9.0, 9.0, 9.0]))

    def test_joints_from_encoders(self, rng):
        q_enc = rng.normal(size=(4, 3, 5))
        offsets = rng.normal(size=5)
        np.testing.assert_allclose(g.joints_from_encoders(q_enc, offsets), q_enc - offsets, atol=0)
        with pytest.raises(InvalidInputError, match="offsets"):
            g.joints_from_encoders(q_enc, np.zeros(4))

    def test_blade_must_be_1_or_2(self, robot):
        for bad in (0, 3, -1):
            with pytest.raises(InvalidInputError, match="blade must be 1 or 2"):
                robot.blade_pose(np.zeros(5), bad)
        with pytest.raises(InvalidInputError, match="blade"):
            robot.jacobian(np.zeros(5), 1.5)  # type: ignore[arg-type]

    def test_pickle_and_repr(self, robot):
        again = pickle.loads(pickle.dumps(robot))
        assert again.params == robot.params
        np.testing.assert_allclose(again.base, robot.base, atol=1e-15)
        assert "WaferRobot(params=RobotParams(" in repr(robot)


# ------------------------------------------------------------------------------------------
# Cameras
# ------------------------------------------------------------------------------------------

W, H = 1280, 720


def random_bc_params(rng: np.random.Generator) -> np.ndarray:
    """Realistic Brown–Conrady parameters: fx, fy, cx, cy, k1, k2, p1, p2, k3."""
    fx = rng.uniform(600, 1200)
    return np.array(
        [
            fx,
            fx * rng.uniform(0.98, 1.02),
            rng.uniform(600, 680),
            rng.uniform(330, 390),
            rng.uniform(-0.3, 0.1),
            rng.uniform(-0.05, 0.1),
            rng.uniform(-1e-3, 1e-3),
            rng.uniform(-1e-3, 1e-3),
            rng.uniform(-0.02, 0.02),
        ]
    )


def random_kb_params(rng: np.random.Generator) -> np.ndarray:
    """Realistic Kannala–Brandt parameters: fx, fy, cx, cy, k1, k2, k3, k4."""
    f = rng.uniform(350, 450)
    return np.array(
        [
            f,
            f * rng.uniform(0.99, 1.01),
            rng.uniform(620, 660),
            rng.uniform(340, 380),
            rng.uniform(-0.05, 0.05),
            rng.uniform(-0.01, 0.01),
            rng.uniform(-0.005, 0.005),
            rng.uniform(-0.001, 0.001),
        ]
    )


def points_in_view(rng: np.random.Generator, n: int, half_angle: float) -> np.ndarray:
    """Points in front of the camera within `half_angle` of the optical axis, depth 0.2–5 m."""
    theta = rng.uniform(0, half_angle, size=n)
    phi = rng.uniform(-math.pi, math.pi, size=n)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return d * rng.uniform(0.2, 5.0, size=(n, 1))


def k_matrix(p: np.ndarray) -> np.ndarray:
    return np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]])


def cv_project(points: np.ndarray, params: np.ndarray, rvec=None, tvec=None) -> np.ndarray:
    rvec = np.zeros(3) if rvec is None else rvec
    tvec = np.zeros(3) if tvec is None else tvec
    dist = np.array(params[[4, 5, 6, 7, 8]]) if len(params) == 9 else np.zeros(5)
    px, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, k_matrix(params), dist)
    return px.reshape(-1, 2)


def cv_fisheye_project(points: np.ndarray, params: np.ndarray, rvec=None, tvec=None) -> np.ndarray:
    rvec = np.zeros((3, 1)) if rvec is None else np.asarray(rvec).reshape(3, 1)
    tvec = np.zeros((3, 1)) if tvec is None else np.asarray(tvec).reshape(3, 1)
    px, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, k_matrix(params), params[4:8])
    return px.reshape(-1, 2)


class TestCamera:
    def test_brown_conrady_matches_opencv(self, rng):
        for _ in range(5):
            params = random_bc_params(rng)
            cam = g.Camera("brown_conrady", params, W, H)
            pts = points_in_view(rng, 500, math.radians(40))
            np.testing.assert_allclose(cam.project(pts), cv_project(pts, params), rtol=0, atol=1e-9)

    def test_brown_conrady_matches_opencv_with_pose(self, rng):
        params = random_bc_params(rng)
        cam = g.Camera("opencv", params, W, H)
        rvec = rng.normal(size=3) * 0.3
        tvec = np.array([0.1, -0.2, 0.3])
        pts_c = points_in_view(rng, 300, math.radians(40))
        # World points that land at pts_c in the camera: X_w = R⁻¹ (X_c − t).
        R = rodrigues(rvec)
        pts_w = (pts_c - tvec) @ R
        T_cw = homogeneous(R, tvec)
        ours = cam.project(pts_w @ T_cw[:3, :3].T + T_cw[:3, 3])
        np.testing.assert_allclose(ours, cv_project(pts_w, params, rvec, tvec), rtol=0, atol=1e-9)

    def test_kannala_brandt_matches_opencv_fisheye(self, rng):
        for _ in range(5):
            params = random_kb_params(rng)
            cam = g.Camera("kannala_brandt", params, W, H)
            pts = points_in_view(rng, 500, math.radians(85))
            np.testing.assert_allclose(cam.project(pts), cv_fisheye_project(pts, params), rtol=0, atol=1e-9)
        rvec, tvec = rng.normal(size=3) * 0.3, np.array([0.05, 0.02, -0.1])
        R = rodrigues(rvec)
        pts_c = points_in_view(rng, 200, math.radians(80))
        pts_w = (pts_c - tvec) @ R
        cam = g.Camera("fisheye", params, W, H)
        np.testing.assert_allclose(
            cam.project(pts_w @ R.T + tvec), cv_fisheye_project(pts_w, params, rvec, tvec), rtol=0, atol=1e-9
        )

    def test_pinhole_matches_opencv(self, rng):
        params = random_bc_params(rng)[:4]
        cam = g.Camera("pinhole", params, W, H)
        pts = points_in_view(rng, 300, math.radians(50))
        np.testing.assert_allclose(cam.project(pts), cv_project(pts, params), rtol=0, atol=1e-9)

    def test_attributes(self, rng):
        params = random_bc_params(rng)
        cam = g.Camera("opencv", params.tolist(), W, H)
        assert cam.model == "brown_conrady"
        assert cam.param_names == ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
        np.testing.assert_array_equal(cam.params, params)
        np.testing.assert_array_equal(cam.K, k_matrix(params))
        assert (cam.width, cam.height) == (W, H)
        assert g.Camera("kb", random_kb_params(rng), W, H).model == "kannala_brandt"
        assert g.Camera("kb", random_kb_params(rng), W, H).param_names == [
            "fx",
            "fy",
            "cx",
            "cy",
            "k1",
            "k2",
            "k3",
            "k4",
        ]
        again = pickle.loads(pickle.dumps(cam))
        np.testing.assert_array_equal(again.params, params)
        assert again.model == cam.model
        assert repr(cam).startswith("Camera('brown_conrady', [")

    def test_in_image(self, rng):
        cam = g.Camera("pinhole", [500, 500, 320, 240], 640, 480)
        px = np.array([[-0.5, -0.5], [-0.51, 0], [639.49, 479.49], [639.5, 0], [0, 479.5], [np.nan, 1.0]])
        np.testing.assert_array_equal(cam.in_image(px), [True, False, True, False, False, False])
        assert cam.in_image([10.0, 10.0]).shape == ()

    @pytest.mark.parametrize(
        ("model", "params_fn", "half_angle"),
        [
            ("pinhole", lambda r: random_bc_params(r)[:4], 40),
            ("brown_conrady", random_bc_params, 35),
            ("kannala_brandt", random_kb_params, 85),
        ],
    )
    def test_project_unproject_round_trip(self, rng, model, params_fn, half_angle):
        cam = g.Camera(model, params_fn(rng), W, H)
        pts = points_in_view(rng, 400, math.radians(half_angle)).reshape(20, 20, 3)
        px = cam.project(pts)
        assert px.shape == (20, 20, 2)
        rays = cam.unproject(px)
        assert rays.shape == (20, 20, 3)
        np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-12)
        np.testing.assert_allclose(rays, pts / np.linalg.norm(pts, axis=-1, keepdims=True), atol=1e-9)
        np.testing.assert_allclose(cam.project(rays), px, atol=1e-8)

    @pytest.mark.parametrize(
        ("model", "params_fn"),
        [
            ("pinhole", lambda r: random_bc_params(r)[:4]),
            ("brown_conrady", random_bc_params),
            ("kannala_brandt", random_kb_params),
        ],
    )
    def test_jacobians_match_finite_differences(self, rng, model, params_fn):
        params = params_fn(rng)
        cam = g.Camera(model, params, W, H)
        pts = points_in_view(rng, 8, math.radians(35))
        px, J_pt, J_par = cam.project_jacobians(pts)
        n = len(params)
        assert px.shape == (8, 2) and J_pt.shape == (8, 2, 3) and J_par.shape == (8, 2, n)
        np.testing.assert_allclose(px, cam.project(pts), atol=0)
        eps = 1e-6
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            num = (cam.project(pts + d) - cam.project(pts - d)) / (2 * eps)
            np.testing.assert_allclose(J_pt[:, :, k], num, rtol=1e-6, atol=1e-4)
        for k in range(n):
            step = eps * max(1.0, abs(params[k]))
            d = np.zeros(n)
            d[k] = step
            plus = g.Camera(model, params + d, W, H).project(pts)
            minus = g.Camera(model, params - d, W, H).project(pts)
            np.testing.assert_allclose(J_par[:, :, k], (plus - minus) / (2 * step), rtol=1e-6, atol=1e-4)

    def test_invalid_cameras(self, rng):
        with pytest.raises(InvalidInputError, match="unknown camera model"):
            g.Camera("orthographic", [1, 1, 0, 0], W, H)
        with pytest.raises(InvalidInputError, match="params"):
            g.Camera("brown_conrady", [500, 500, 320, 240], W, H)
        with pytest.raises(InvalidInputError, match="fx"):
            g.Camera("pinhole", [-500, 500, 320, 240], W, H)
        with pytest.raises(InvalidInputError, match="width"):
            g.Camera("pinhole", [500, 500, 320, 240], 0, H)
        with pytest.raises(InvalidInputError, match="height"):
            g.Camera("pinhole", [500, 500, 320, 240], W, 2.5)  # type: ignore[arg-type]
        with pytest.raises(InvalidInputError, match="model"):
            g.Camera(3, [500, 500, 320, 240], W, H)  # type: ignore[arg-type]

    def test_point_behind_pinhole_camera(self):
        cam = g.Camera("pinhole", [500, 500, 320, 240], 640, 480)
        with pytest.raises(InvalidInputError, match="cannot project"):
            cam.project([[0.0, 0.0, 1.0], [0.1, 0.2, -1.0]])


# ------------------------------------------------------------------------------------------
# Ellipses and circles
# ------------------------------------------------------------------------------------------


def conic_closed_form(cx, cy, a, b, theta) -> np.ndarray:
    """Eq. (3.1) written out: ((x'/a)² + (y'/b)² − 1) with x', y' in the ellipse frame."""
    c, s = math.cos(theta), math.sin(theta)
    # x' = c (x − cx) + s (y − cy), y' = −s (x − cx) + c (y − cy); p = [x, y, 1].
    A = np.array([[c, s, -(c * cx + s * cy)], [-s, c, -(-s * cx + c * cy)]])
    return A.T @ np.diag([1 / a**2, 1 / b**2]) @ A - np.diag([0, 0, 1.0])


class TestEllipse:
    def test_attributes_and_canonical_form(self):
        e = g.Ellipse(320, 240, 50, 100, 0.3)  # a < b: axes swapped, theta turned by π/2
        assert (e.a, e.b) == (100.0, 50.0)
        assert e.theta == pytest.approx(0.3 - math.pi / 2, abs=1e-15)
        np.testing.assert_array_equal(e.center, [320, 240])
        np.testing.assert_allclose(e.as_array(), [320, 240, 100, 50, 0.3 - math.pi / 2])
        again = g.Ellipse.from_array(e.as_array())
        np.testing.assert_array_equal(again.as_array(), e.as_array())
        assert eval(repr(e), {"Ellipse": g.Ellipse}).as_array().tolist() == e.as_array().tolist()
        assert pickle.loads(pickle.dumps(e)).as_array().tolist() == e.as_array().tolist()
        assert e.area == pytest.approx(math.pi * 100 * 50, rel=1e-15)
        with pytest.raises(InvalidInputError, match="semi-axis"):
            g.Ellipse(0, 0, 1.0, -1.0, 0)
        with pytest.raises(InvalidInputError, match="values"):
            g.Ellipse.from_array([1, 2, 3])

    def test_conic_matches_closed_form_and_round_trips(self, rng):
        for _ in range(20):
            params = (rng.uniform(0, 640), rng.uniform(0, 480), *sorted(rng.uniform(5, 200, 2))[::-1])
            e = g.Ellipse(*params, rng.uniform(-1.5, 1.5))
            C = e.conic()
            np.testing.assert_allclose(C, conic_closed_form(e.cx, e.cy, e.a, e.b, e.theta), rtol=1e-12, atol=1e-12)
            for scale in (1.0, -7.0, 1e-6):
                back = g.Ellipse.from_conic(C * scale)
                np.testing.assert_allclose(back.as_array(), e.as_array(), rtol=1e-9, atol=1e-9)
            coef = e.conic_coefficients()
            np.testing.assert_allclose(np.linalg.norm(coef), 1.0, atol=1e-15)
            A, B, Cc, D, E, F = coef
            M = np.array([[A, B / 2, D / 2], [B / 2, Cc, E / 2], [D / 2, E / 2, F]])
            np.testing.assert_allclose(M / np.linalg.norm(M), C / np.linalg.norm(C), atol=1e-12)

    def test_distance_zero_on_sampled_points(self):
        e = g.Ellipse(300.5, 200.25, 120, 45, 0.4)
        pts = e.sample(64, 0.0, 2 * math.pi)
        assert pts.shape == (64, 2)
        np.testing.assert_allclose(pts[0], pts[-1], atol=1e-12)
        for kind in ("orthogonal", "sampson", "algebraic"):
            np.testing.assert_allclose(e.distance(pts, kind=kind), 0.0, atol=1e-9)
        np.testing.assert_allclose(e.point_at(np.linspace(0, 2 * math.pi, 64)), pts, atol=1e-12)
        np.testing.assert_allclose(e.closest_point(pts), pts, atol=1e-9)

    def test_orthogonal_distance_and_closest_point_vs_brute_force(self, rng):
        e = g.Ellipse(10.0, -5.0, 30.0, 12.0, -0.7)
        curve = e.sample(400_001, 0.0, 2 * math.pi)
        pts = np.array([e.cx, e.cy]) + rng.normal(size=(60, 2)) * 25
        d = e.distance(pts)
        closest = e.closest_point(pts)
        for p, di, ci in zip(pts, d, closest, strict=True):
            dist = np.linalg.norm(curve - p, axis=1)
            k = dist.argmin()
            inside = e.distance(p, kind="algebraic") < 0
            assert abs(abs(di) - dist[k]) < 1e-6
            assert (di < 0) == inside
            assert np.linalg.norm(ci - p) <= dist[k] + 1e-9
        # At the centre: one semi-minor axis inside.
        assert e.distance([e.cx, e.cy]) == pytest.approx(-12.0, abs=1e-12)

    def test_sampson_and_algebraic(self, rng):
        e = g.Ellipse(0.0, 0.0, 40.0, 25.0, 0.2)
        on = e.sample(50, 0, 2 * math.pi)
        # Points 0.01 px off the curve along the outward normal (gradient of the conic).
        C = e.conic()
        hom = np.concatenate([on, np.ones((50, 1))], axis=1)
        normal = (hom @ C)[:, :2]
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        near = on + 0.01 * normal
        np.testing.assert_allclose(e.distance(near, "sampson"), 0.01, rtol=1e-3)
        np.testing.assert_allclose(e.distance(near, "orthogonal"), 0.01, rtol=1e-9)
        pts = rng.normal(size=(4, 5, 2)) * 50
        hom = np.concatenate([pts, np.ones((4, 5, 1))], axis=-1)
        alg = np.einsum("...i,ij,...j->...", hom, C, hom)
        np.testing.assert_allclose(e.distance(pts, "algebraic"), alg, rtol=1e-9, atol=1e-12)
        assert e.distance(pts, "sampson").shape == (4, 5)
        with pytest.raises(InvalidInputError, match="kind"):
            e.distance(pts, "euclid")  # type: ignore[arg-type]

    def test_from_conic_rejects_non_ellipses(self):
        hyperbola = np.diag([1.0, -1.0, -1.0])  # x² − y² = 1
        with pytest.raises(DegenerateGeometryError, match="hyperbola"):
            g.Ellipse.from_conic(hyperbola)
        with pytest.raises(DegenerateGeometryError):
            g.Ellipse.from_conic(np.diag([1.0, 1.0, 1.0]))  # imaginary: x² + y² = −1
        with pytest.raises(DegenerateGeometryError):
            g.Ellipse.from_conic(np.zeros((3, 3)))
        with pytest.raises(InvalidInputError, match="C must have shape"):
            g.Ellipse.from_conic(np.eye(2))
        # Regression: an asymmetric matrix silently gave the unit circle of its symmetric part.
        with pytest.raises(InvalidInputError, match="symmetric"):
            g.Ellipse.from_conic([[1.0, 5.0, 0.0], [-5.0, 1.0, 0.0], [0.0, 0.0, -1.0]])

    def test_sample_of_more_points_than_memory_is_an_error(self):
        # Regression: 2**62 points hit a capacity-overflow panic (InternalError).
        with pytest.raises(MemoryError, match="ellipse sample points"):
            g.Ellipse(0, 0, 2, 1, 0).sample(2**62)

    def test_huge_rotations_are_refused_or_finite(self):
        # Regression: R·1e200 overflowed RᵀR to NaN, passed the orthonormality check and hung.
        R = g.so3_exp([0.3, 0.2, 0.1]) * 1e200
        for call in (g.so3_log, g.matrix_to_quat, g.matrix_to_euler_zyx):
            with pytest.raises(InvalidInputError, match="not a rotation"):
                call(R)
        T = np.eye(4)
        T[:3, :3] = R
        with pytest.raises(InvalidInputError, match="not a rigid transform"):
            g.se3_log(T)
        # exp of a huge rotation vector is the exact rotation by that angle, not NaN.
        np.testing.assert_allclose(
            g.so3_exp([1e200, 0.0, 0.0]),
            [[1, 0, 0], [0, np.cos(1e200), -np.sin(1e200)], [0, np.sin(1e200), np.cos(1e200)]],
            atol=1e-12,
        )
        assert np.all(np.isfinite(g.se3_exp([3e200, 1e200, 2e200, 1.0, 2.0, 3.0])))

    def test_sample_needs_two_points(self):
        with pytest.raises(InvalidInputError, match="n must be at least 2"):
            g.Ellipse(0, 0, 2, 1, 0).sample(1)


K_TEST = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])


def circle_points(center, normal, radius, n=36) -> np.ndarray:
    z = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    x = np.cross(z, [0.3, 0.5, 0.8])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    t = np.linspace(0, 2 * math.pi, n, endpoint=False)[:, None]
    return np.asarray(center) + radius * (np.cos(t) * x + np.sin(t) * y)


def pinhole(K: np.ndarray, pts_c: np.ndarray) -> np.ndarray:
    uvw = pts_c @ K.T
    return uvw[:, :2] / uvw[:, 2:]


class TestProjectCircle:
    def test_projected_rim_points_lie_on_the_ellipse(self, rng):
        for _ in range(10):
            T_cw = random_pose(rng, angle=0.3, dist=0.1)
            T_cw[2, 3] += 1.0  # world origin about 1 m in front of the camera
            center = rng.uniform(-0.1, 0.1, size=3)
            normal = rng.normal(size=3) * 0.2 + [0, 0, 1.0]
            r = rng.uniform(0.05, 0.15)
            e = g.project_circle(K_TEST, T_cw, center, normal, r)
            pts_w = circle_points(center, normal, r)
            pts_c = pts_w @ T_cw[:3, :3].T + T_cw[:3, 3]
            px = pinhole(K_TEST, pts_c)
            np.testing.assert_allclose(e.distance(px), 0.0, atol=1e-9)
            # The same through Camera("pinhole").
            cam = g.Camera("pinhole", [800.0, 780.0, 320.0, 240.0], 640, 480)
            np.testing.assert_allclose(e.distance(cam.project(pts_c)), 0.0, atol=1e-9)

    def test_circle_image_conic_and_jacobian(self, rng):
        T_co = homogeneous(rot_x(0.5) @ rot_y(-0.2), [0.05, -0.03, 0.8])
        r = 0.15
        C = g.circle_image_conic(K_TEST, T_co, r)
        rim = circle_points([0, 0, 0], [0, 0, 1], r)
        px = pinhole(K_TEST, rim @ T_co[:3, :3].T + T_co[:3, 3])
        hom = np.concatenate([px, np.ones((len(px), 1))], axis=1)
        np.testing.assert_allclose(np.einsum("ni,ij,nj->n", hom, C, hom), 0.0, atol=1e-12)
        e, J = g.project_circle_jacobian(K_TEST, T_co, r)
        assert J.shape == (5, 6)
        np.testing.assert_allclose(e.as_array(), g.Ellipse.from_conic(C).as_array(), atol=1e-9)
        eps = 1e-7
        num = np.zeros((5, 6))
        for i in range(6):
            d = np.zeros(6)
            d[i] = eps
            ep = g.project_circle_jacobian(K_TEST, g.se3_plus(T_co, d), r)[0].as_array()
            em = g.project_circle_jacobian(K_TEST, g.se3_plus(T_co, -d), r)[0].as_array()
            diff = ep - em
            diff[4] = wrap(diff[4] + math.pi / 2) - math.pi / 2  # theta is defined modulo π
            num[:, i] = diff / (2 * eps)
        np.testing.assert_allclose(J, num, rtol=1e-5, atol=1e-4)

    def test_edge_on_circle_is_degenerate(self):
        # The camera centre lies in the circle's plane: its image is a line segment.
        T_cw = np.eye(4)
        with pytest.raises(DegenerateGeometryError):
            g.project_circle(K_TEST, T_cw, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 0.1)

    def test_invalid_circle(self):
        with pytest.raises(InvalidInputError, match="normal"):
            g.project_circle(K_TEST, np.eye(4), [0, 0, 1.0], [0, 0, 0], 0.1)
        with pytest.raises(InvalidInputError, match="radius"):
            g.project_circle(K_TEST, np.eye(4), [0, 0, 1.0], [0, 0, 1.0], -0.1)
        with pytest.raises(InvalidInputError, match="radius"):
            g.project_circle(K_TEST, np.eye(4), [0, 0, 1.0], [0, 0, 1.0], float("inf"))


# ------------------------------------------------------------------------------------------
# Bad input: every entry point names the argument, never panics
# ------------------------------------------------------------------------------------------

_ROBOT = g.WaferRobot()
_CAM = g.Camera("brown_conrady", [800, 800, 640, 360, -0.1, 0.01, 1e-4, -1e-4, 0.0], W, H)
_ELL = g.Ellipse(320, 240, 100, 50, 0.2)

# (call taking one argument, argument name, a valid value, item shape)
ENTRY_POINTS = [
    (g.so3_exp, "omega", np.array([0.1, 0.2, 0.3]), (3,)),
    (g.so3_log, "R", np.eye(3), (3, 3)),
    (g.se3_exp, "xi", np.full(6, 0.1), (6,)),
    (g.se3_log, "T", np.eye(4), (4, 4)),
    (lambda x: g.se3_plus(np.eye(4), x), "xi", np.full(6, 0.1), (6,)),
    (lambda x: g.se3_minus(x, np.eye(4)), "Y", np.eye(4), (4, 4)),
    (g.quat_to_matrix, "q", np.array([1.0, 0, 0, 0]), (4,)),
    (g.matrix_to_quat, "R", np.eye(3), (3, 3)),
    (g.euler_zyx_to_matrix, "angles", np.zeros(3), (3,)),
    (g.matrix_to_euler_zyx, "R", np.eye(3), (3, 3)),
    (_ROBOT.camera_pose, "q", np.zeros(5), (5,)),
    (lambda q: _ROBOT.blade_pose(q, 2), "q", np.zeros(5), (5,)),
    (_ROBOT.camera_jacobian, "q", np.zeros(5), (5,)),
    (lambda q: _ROBOT.acceleration(np.zeros(5), q, np.zeros(5)), "qd", np.zeros(5), (5,)),
    (lambda T: _ROBOT.inverse_kinematics(T, 1), "T", _ROBOT.blade_pose(np.array([0.3, 1, 0, 0, 0]), 1), (4, 4)),
    (lambda q: g.joints_from_encoders(q, np.zeros(5)), "q_enc", np.zeros(5), (5,)),
    (_CAM.project, "points", np.array([0.1, 0.2, 1.0]), (3,)),
    (_CAM.unproject, "pixels", np.array([600.0, 300.0]), (2,)),
    (_CAM.project_jacobians, "points", np.array([0.1, 0.2, 1.0]), (3,)),
    (_ELL.distance, "points", np.array([1.0, 2.0]), (2,)),
    (_ELL.closest_point, "points", np.array([1.0, 2.0]), (2,)),
    (g.Ellipse.from_conic, "C", _ELL.conic(), (3, 3)),
    (lambda c: g.project_circle(K_TEST, np.eye(4), c, [0, 0, 1.0], 0.1), "center", np.array([0, 0, 1.0]), (3,)),
    (lambda k: g.project_circle(k, np.eye(4), [0, 0, 1.0], [0, 0, 1.0], 0.1), "K", K_TEST, (3, 3)),
]
IDS = [f"{i}-{name}" for i, (_, name, _, _) in enumerate(ENTRY_POINTS)]


def _wrong_shapes(item: tuple[int, ...]) -> list[tuple[int, ...]]:
    """Shapes that must be rejected for an item shape: a wrong last axis, and too few axes."""
    wrong = [item[:-1] + (item[-1] + 1,), (), item[1:] if len(item) > 1 else (2, 2)]
    if item == (2,):
        wrong[2] = (2, 3)
    return [s for s in wrong if s != item]


@pytest.mark.parametrize(("fn", "name", "valid", "item"), ENTRY_POINTS, ids=IDS)
class TestBadInput:
    def test_valid_input_in_many_forms(self, fn, name, valid, item):
        ref = fn(valid)
        for form in (valid.tolist(), tuple(valid.tolist()), valid.astype(np.float32), np.asfortranarray(valid)):
            out = fn(form)
            if isinstance(ref, g.Ellipse):
                np.testing.assert_allclose(out.as_array(), ref.as_array(), rtol=1e-6)
            elif isinstance(ref, tuple):
                for a, b in zip(out, ref, strict=True):
                    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
            else:
                np.testing.assert_allclose(out, ref, rtol=1e-5, atol=1e-6)

    def test_wrong_shape(self, fn, name, valid, item):
        for shape in _wrong_shapes(item):
            with pytest.raises(InvalidInputError, match=rf"^{name}\b.*shape"):
                fn(np.zeros(shape) + 0.5)

    @pytest.mark.parametrize(
        "bad",
        [
            "abc",
            b"abc",
            object(),
            np.array(["a", "b", "c"]),
            np.zeros(3, dtype=complex),
            np.zeros(3, dtype=bool),
            [1.0, "x", 2.0],
            [[1.0, 2.0], [3.0]],
            None,
        ],
        ids=["str", "bytes", "object", "str-array", "complex", "bool", "mixed-list", "ragged", "None"],
    )
    def test_wrong_type(self, fn, name, valid, item, bad):
        with pytest.raises(InvalidInputError, match=rf"^{name}\b"):
            fn(bad)

    @pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
    def test_non_finite(self, fn, name, valid, item, value):
        bad = np.array(valid, dtype=float)
        bad.flat[-1] = value
        with pytest.raises(InvalidInputError, match=rf"^{name}\b.*must be finite"):
            fn(bad)
        batch = np.stack([valid, bad])
        with pytest.raises(InvalidInputError, match=rf"^{name}\b.*must be finite"):
            fn(batch)


SCALAR_ARGS = [
    (lambda x: g.Ellipse(x, 0.0, 2.0, 1.0, 0.0), "cx"),
    (lambda x: g.Ellipse(0.0, 0.0, 2.0, 1.0, x), "theta"),
    (lambda x: g.Ellipse(0, 0, 2, 1, 0).sample(5, x, 1.0), "t0"),
    (lambda x: g.project_circle(K_TEST, np.eye(4), [0, 0, 1.0], [0, 0, 1.0], x), "radius"),
    (lambda x: g.project_circle_jacobian(K_TEST, np.eye(4), x), "radius"),
    (lambda x: g.WaferRobot().inverse_kinematics(np.eye(4), 1, x), "other_blade_angle"),
    (lambda x: g.WaferRobot().inverse_kinematics_camera(np.eye(4), x), "theta3"),
    (lambda x: g.RobotParams(cam_d=x), "cam_d"),
    (lambda x: g.WaferRobot({"l3": x}), "l3"),
]


@pytest.mark.parametrize(("fn", "name"), SCALAR_ARGS, ids=[f"{i}-{n}" for i, (_, n) in enumerate(SCALAR_ARGS)])
@pytest.mark.parametrize(
    "bad",
    ["0.1", None, 1j, [0.1, 0.2], np.nan, np.inf, True],
    ids=["str", "None", "complex", "list", "nan", "inf", "bool"],
)
def test_bad_scalar_arguments(fn, name, bad):
    with pytest.raises(InvalidInputError, match=rf"^{name}\b"):
        fn(bad)


def test_robot_params_are_validated_by_the_rust_rules():
    with pytest.raises(InvalidInputError, match="l1 = -1"):
        g.RobotParams(l1=-1)
    with pytest.raises(InvalidInputError, match="beta_c"):
        g.RobotParams(beta_c=math.pi / 2)
    p = g.RobotParams(l1=1)
    assert isinstance(p.l1, float)


class TestCompiledLayer:
    """The compiled functions take float64 arrays only and never panic."""

    def test_float64_only(self):
        with pytest.raises(
            InvalidInputError, match="omega must be a float64 NumPy array, got an array of dtype float32"
        ):
            _core.so3_exp(np.zeros(3, dtype=np.float32))
        with pytest.raises(InvalidInputError, match="omega must be a float64 NumPy array, got a list"):
            _core.so3_exp([0.0, 1.0, 2.0])
        # Non-contiguous float64 views are read correctly.
        omega = np.zeros((4, 6))
        omega[:, ::2] = [[0.1, 0.2, 0.3]] * 4
        np.testing.assert_allclose(_core.so3_exp(omega[:, ::2]), g.so3_exp([0.1, 0.2, 0.3])[None].repeat(4, 0))
        T_fortran = np.asfortranarray(g.se3_exp(np.full((3, 6), 0.1)))
        assert not T_fortran.flags.c_contiguous
        np.testing.assert_allclose(_core.se3_log(T_fortran), 0.1, atol=1e-15)

    def test_bad_scalars_and_sizes(self):
        with pytest.raises(InvalidInputError, match="width"):
            _core.Camera("pinhole", np.array([1.0, 1, 1, 1]), -1, 3)
        with pytest.raises(InvalidInputError, match=r"params must have shape \(4,\)"):
            _core.Camera("pinhole", np.array([1.0, 1, 1]), 1, 3)
        with pytest.raises(InvalidInputError, match="must be finite|non-finite"):
            _core.Ellipse(0, 0, 1, 1, float("nan"))
        with pytest.raises(InvalidInputError, match="n must be at least 2"):
            _core.Ellipse(0, 0, 2, 1, 0).sample(-3, 0.0, 1.0)
        with pytest.raises(InvalidInputError, match="other_blade_angle"):
            _core.WaferRobot().inverse_kinematics(np.eye(4), 1, float("inf"))

    def test_batch_errors_name_the_element(self):
        cam = g.Camera("pinhole", [500, 500, 320, 240], 640, 480)
        with pytest.raises(InvalidInputError, match=r"^element 1: cannot project point \(0, 0, -1\)"):
            cam.project([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
        with pytest.raises(InvalidInputError, match=r"^cannot project point"):
            cam.project([0.0, 0.0, -1.0])


def test_large_batches_release_the_gil():
    """Another Python thread runs while a large batched call is computing."""
    cam = g.Camera("brown_conrady", [800, 800, 640, 360, -0.2, 0.05, 1e-4, -1e-4, 0.01], W, H)
    px = np.random.default_rng(1).uniform([0, 0], [W, H], size=(2_000_000, 2))
    stamps: list[float] = []
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            stamps.append(time.perf_counter())

    thread = threading.Thread(target=spin)
    thread.start()
    time.sleep(0.01)
    # Repeat the call until at least 0.3 s were spent inside it, so the check means something
    # on a fast machine too; with the GIL held, the other thread could only run at the edges of
    # a call (one switch interval, 5 ms), never well inside it.
    windows: list[tuple[float, float]] = []
    while sum(t1 - t0 for t0, t1 in windows) < 0.3:
        t0 = time.perf_counter()
        cam.unproject(px)
        windows.append((t0, time.perf_counter()))
    stop.set()
    thread.join()
    assert any(t0 + 0.02 < t < t1 - 0.02 for t0, t1 in windows for t in stamps)
