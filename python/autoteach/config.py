"""The options of auto-teaching in one place: :class:`AutoteachConfig` and its explained defaults.

Every number the pipeline falls back on when a session does not say it (a log of a real robot has
no simulator configuration) is a named constant here, with the reason for its value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from autoteach.errors import InvalidInputError
from autoteach.options import checked_replace

__all__ = [
    "DEFAULT_ENCODER_NOISE",
    "DEFAULT_OFFSETS",
    "DEFAULT_SLOT_PITCH",
    "DEFAULT_SLOT_COUNT",
    "DEFAULT_WAFER_RADIUS",
    "DEFAULT_WAFER_THICKNESS",
    "JOINTS",
    "LINKS",
    "PIXEL_SIGMA_FLOOR",
    "AutoteachConfig",
]

#: Joint names in the order of the joint vector ``q = (θ1, θ2, θ3, θ4, h)``.
JOINTS: tuple[str, ...] = ("joint1", "joint2", "joint3", "joint4", "lift")
#: Link lengths that SLAM-MOT can calibrate (``estimate_links``).
LINKS: tuple[str, ...] = ("l1", "l2", "l4")
#: Offsets SLAM-MOT estimates by default: the observable ones (see :mod:`autoteach.pipeline`).
DEFAULT_OFFSETS: tuple[str, ...] = ("joint2", "joint4")
#: Carrier slot pitch (m) when the session does not give it: 10 mm, the pitch of a 300 mm FOUP.
DEFAULT_SLOT_PITCH = 0.010
#: Carrier slots when the session does not give them: the simulator's carrier (26 slots, numbered
#: from the bottom); only the slot-birth hypotheses of the tracker use it.
DEFAULT_SLOT_COUNT = 26
#: Wafer radius (m) when the session does not give it: a 300 mm wafer.
DEFAULT_WAFER_RADIUS = 0.150
#: Wafer thickness (m) when the session does not give it: the simulator's 1 mm. A 300 mm silicon
#: wafer is 0.775 mm thick; give ``wafer_thickness`` for a real robot.
DEFAULT_WAFER_THICKNESS = 0.001
#: Encoder noise (rad ×4, m) when the session does not give it: the simulator's encoders.
DEFAULT_ENCODER_NOISE: tuple[float, ...] = (2e-5, 2e-5, 2e-5, 2e-5, 5e-6)
#: Smallest edge-point σ (px) the solver assumes. The detector's white edge noise is about
#: 0.06 px, but its structured error along an edge (the side-face band, docs/design/handeye.md)
#: is larger and correlated, which a model of independent points cannot represent.
PIXEL_SIGMA_FLOOR = 0.3


@dataclass(frozen=True)
class AutoteachConfig:
    """Options of :func:`autoteach.pipeline.autoteach`, with the defaults of the demo.

    ``None`` means "from the session, else the documented default".

    Attributes:
        frontend: ``"simulated"`` (ground-truth visible rims of a simulated session with pixel
            noise and ground-truth association), ``"detect"`` (wafer detection + tracking on the
            images, gated by the projected prior: the real pipeline) or ``"auto"`` (``"detect"``
            when the session has images, else ``"simulated"`` when it has ground-truth rims).
        points_per_rim: edge points kept per rim and frame.
        pixel_noise: std of the noise added by the simulated front end (pixels).
        pixel_sigma: edge-point std assumed by the solver (default:
            ``max(pixel_noise, PIXEL_SIGMA_FLOOR)``).
        min_axis_ratio: rims seen more edge-on than this minor/major ratio are dropped.
        estimate_offsets: joints whose zero offsets SLAM-MOT estimates (asking for ``joint1``,
            ``joint3`` or ``lift`` makes the problem unobservable, which is reported).
        window: sliding-window size in frames (0: batch only).
        nominal_base: nominal ``T_wb`` (4×4) in the reference-wafer frame (default: the simulated
            configuration's base pose moved into the reference frame of the nominal slot).
        robot_params: robot geometry (default: the session's, or the default robot).
        wafer_radius: wafer radius (m; default: the session's or :data:`DEFAULT_WAFER_RADIUS`).
        wafer_thickness: wafer thickness (m; default: the session's or
            :data:`DEFAULT_WAFER_THICKNESS`).
        odometry: visual-odometry increments (F−1, 6) ``[u_T; u_R]`` for the UKF; simulated
            sessions without them get drifting simulated odometry.
        odometry_sigma: precision of the odometry increments ``[σ_ω (3, rad); σ_ρ (3, m)]`` for
            the free-camera mode's relative-pose factors (default: the simulated odometry's white
            noise plus its drift over the session when the pipeline simulates it, else the
            per-step process noise of eq. (5.2): 0.2°, 30/30/1.5 mm).
        odometry_start: orientation (3×3, or the rotation of a 4×4 pose) of the first camera
            frame in the odometry's world frame (free-camera mode; default: the nominal chain's at
            frame 0 for given odometry, the true one for simulated odometry).
        use_ukf: run the UKF stage (needs odometry).
        ukf_noise: ``"seed"`` for the noise levels of eq. (5.2), 16 standard deviations, or
            ``None``: matched to the simulated odometry when the pipeline simulates it.
        ukf_odometry: ``"vo"`` (world-frame increments with white errors, eq. (5.1)) or
            ``"slam"`` (relative poses of a SLAM with a map; θ1 is then unobservable).
        baseline: also solve with point reprojection and nearest-point association.
        huber: Huber threshold on whitened residuals (``None``: none).
        encoder_sigma: encoder noise of joint1, joint2, joint4, lift modelled per frame (default:
            the session's, else :data:`DEFAULT_ENCODER_NOISE`; ``()`` ties the camera rigidly to
            the encoders).
        max_iterations: LM iteration limit.
        min_track_frames: detect front end: tracks registered in fewer frames are not used for
            the first estimate.
        min_wafer_frames: detect front end: wafers gated into fewer frames are reported as not
            estimated.
        reset_tilts: detect front end: also run the gating chain from level wafers after the first
            estimate and keep the chain that explains more edges.
        basin_search: after every batch solve, re-fit each wafer whose edge residuals stand out
            from a grid of tilts and heights (``SlamMot::solve_batch_with_basins``).
        gate_px: detect front end: the gates (pixels) of the re-association rounds.
        min_band_px: detect front end: edge points where the predicted side-face band is narrower
            than this (pixels) are not used in the last gate (0 keeps them).
        band_weights: detect front end: in the last gate every point gets ``σ·s(b)`` from the
            predicted band width ``b`` (the detector's measured edge noise).
        slot_births: detect front end: free slots next to a track are birth hypotheses.
        camera_mode: ``"chain"`` (camera poses through the kinematic chain, eq. (5.9)) or
            ``"free"`` (a pose per frame tied by eqs. (5.10)–(5.12) and the odometry).
        motion_sigma: free-camera mode: robot motion precision ``[σ_ω (3, rad); σ_ρ (3, m)]``.
        estimate_mount: also estimate a correction of the camera mount ``T_ec`` (chain mode).
        estimate_links: link lengths to calibrate, among ``"l1"``, ``"l2"``, ``"l4"``.
        rim_offset_prior: detect front end: give the detector the wafer's thickness ratio, the
            focal length and the camera's edge profile.
        seed: seed of the simulated front end's noise and odometry.
    """

    frontend: str = "auto"
    points_per_rim: int = 24
    pixel_noise: float = 0.3
    pixel_sigma: float | None = None
    min_axis_ratio: float = 0.05
    estimate_offsets: tuple[str, ...] = DEFAULT_OFFSETS
    window: int = 5
    nominal_base: Any = None
    robot_params: Any = None
    wafer_radius: float | None = None
    wafer_thickness: float | None = None
    odometry: Any = None
    odometry_sigma: tuple[float, ...] | None = None
    odometry_start: Any = None
    use_ukf: bool = True
    ukf_noise: Any = None
    ukf_odometry: str = "vo"
    baseline: bool = False
    huber: float | None = 3.0
    encoder_sigma: tuple[float, ...] | None = None
    max_iterations: int = 100
    min_track_frames: int = 5
    min_wafer_frames: int = 8
    reset_tilts: bool = True
    basin_search: bool = True
    gate_px: tuple[float, ...] = (3.0, 1.5, 1.0)
    min_band_px: float = 2.5
    band_weights: bool = True
    slot_births: bool = True
    camera_mode: str = "chain"
    motion_sigma: tuple[float, ...] = (2e-5,) * 6
    estimate_mount: bool = False
    estimate_links: tuple[str, ...] = ()
    rim_offset_prior: bool = True
    seed: int = 0

    def replace(self, **changes: Any) -> AutoteachConfig:
        """A copy with ``changes``; an unknown option name is an error that lists the known ones."""
        return checked_replace(self, "auto-teaching", changes)

    def validate(self) -> None:
        """Check the options that do not depend on the session.

        Raises:
            InvalidInputError: an unknown joint, link, front end, camera mode or odometry kind, or
                a negative band threshold, or mount/link calibration in the free-camera mode.
        """
        bad = [j for j in self.estimate_offsets if j not in JOINTS]
        if bad:
            raise InvalidInputError(f"estimate_offsets names unknown joints {bad}; joints are {JOINTS}")
        if self.frontend not in ("auto", "simulated", "detect"):
            raise InvalidInputError(f"frontend must be 'auto', 'simulated' or 'detect', got {self.frontend!r}")
        if not (math.isfinite(self.min_band_px) and self.min_band_px >= 0.0):
            raise InvalidInputError(f"min_band_px must be finite and >= 0, got {self.min_band_px!r}")
        if self.camera_mode not in ("chain", "free"):
            raise InvalidInputError(f"camera_mode must be 'chain' or 'free', got {self.camera_mode!r}")
        bad_links = [name for name in self.estimate_links if name not in LINKS]
        if bad_links:
            raise InvalidInputError(f"estimate_links names unknown links {bad_links}; links are {LINKS}")
        if self.camera_mode == "free" and (self.estimate_mount or self.estimate_links):
            raise InvalidInputError(
                "the camera mount and link lengths are calibrated through the chain (camera_mode='chain')"
            )
        if self.use_ukf and self.ukf_odometry not in ("vo", "slam"):
            raise InvalidInputError(f"ukf_odometry must be 'vo' or 'slam', got {self.ukf_odometry!r}")
