"""Errors of an auto-teaching result against a simulated session's ground truth.

Kept apart from the pipeline: a log of a real robot has no ground truth, and the estimate never
depends on this module. Errors are computed in the true reference-wafer frame after aligning the
estimate's yaw gauge to the truth (000_3b1454b2b2194811.txt §5.4, Table 5.1).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from autoteach.errors import InvalidInputError
from autoteach.poses import axis_rotation, log_so3, wafer_params_of, wafer_pose

__all__ = ["ground_truth_errors", "match_truth"]


def match_truth(session: Any, slots: np.ndarray, seen: list[int]) -> tuple[list[int], dict[str, list[int]]]:
    """The ground-truth wafer of each estimated wafer, matched by carrier slot.

    Returns ``truth_index`` (``-1`` for an estimated wafer in a slot the truth leaves empty) and
    the slots the estimate missed (``true_slots_missed``) or invented (``spurious_slots``).
    """
    true_slots = [int(v) for v in session.wafer_slots]
    truth_index = [true_slots.index(int(sl)) if int(sl) in true_slots else -1 for sl in slots]
    report = {
        "true_slots_missed": sorted(set(true_slots) - {int(v) for v in slots[seen]}),
        "spurious_slots": [int(slots[w]) for w in seen if truth_index[w] < 0],
    }
    return truth_index, report


def _yaw(r: np.ndarray) -> float:
    """Yaw of a rotation about the world z axis (rad)."""
    return math.atan2(r[1, 0], r[0, 0])


def ground_truth_errors(
    session: Any,
    ref: int,
    base_hat: np.ndarray,
    offsets_hat: np.ndarray,
    wafers_hat: np.ndarray,
    est_idx: list[int],
    seen: list[int],
    base_std: np.ndarray | None = None,
    offsets_std: np.ndarray | None = None,
    wafer_std: np.ndarray | None = None,
    truth_index: list[int] | None = None,
) -> tuple[dict[str, float], dict[str, bool]]:
    """Absolute errors of the estimates against a simulated session's ground truth.

    The truth is moved into the true reference-wafer frame; the effective base is
    ``T_wb·Rz(−δ1)·Tz(−δh)``; the estimate's yaw gauge is aligned to the truth by a rotation about
    the reference normal. Returns the errors (``joint_offset_deg`` max over the estimated
    joints, ``base_translation_mm``, ``base_rotation_deg``, ``wafer_center_mm`` and
    ``wafer_tilt_deg`` max over the wafers) and, when standard deviations are given, whether each
    group's every component lies within 3σ. ``truth_index[w]`` is the ground-truth wafer of
    estimated wafer ``w`` (default: the same index; ``-1``: a wafer the truth does not have,
    skipped — the caller reports it).
    """
    cal = session.calibration
    truth = list(range(len(session.wafer_poses))) if truth_index is None else list(truth_index)
    if truth[ref] < 0:
        raise InvalidInputError("the reference wafer matches no ground-truth wafer: errors cannot be computed")
    t_ref = np.asarray(session.wafer_poses[truth[ref]], dtype=np.float64)
    t_ref_inv = np.linalg.inv(t_ref)
    delta = np.asarray(cal.joint_offsets, dtype=np.float64)
    eff = np.eye(4)
    eff[:3, :3] = axis_rotation("z", -delta[0])
    eff[2, 3] = -delta[4]
    base_true = t_ref_inv @ np.asarray(cal.base_pose, dtype=np.float64) @ eff
    # Gauge: rotate the estimate about the reference normal (z) to the true base yaw.
    g = np.eye(4)
    g[:3, :3] = axis_rotation("z", _yaw(base_true[:3, :3]) - _yaw(base_hat[:3, :3]))
    base_al = g @ base_hat
    d_rot = log_so3(base_true[:3, :3].T @ base_al[:3, :3])
    d_t = base_al[:3, 3] - base_true[:3, 3]
    errs: dict[str, float] = {
        "joint_offset_deg": float(np.degrees(np.max(np.abs(offsets_hat[est_idx] - delta[est_idx]))))
        if est_idx
        else 0.0,
        "base_translation_mm": float(np.linalg.norm(d_t) * 1e3),
        "base_rotation_deg": float(np.degrees(np.linalg.norm(d_rot))),
    }
    centre_err, tilt_err = [], []
    centre_ok, tilt_ok = True, True
    for w in seen:
        if w == ref or truth[w] < 0:
            continue
        wt = t_ref_inv @ np.asarray(session.wafer_poses[truth[w]], dtype=np.float64)
        c_hat = (g @ np.append(wafers_hat[w, :3], 1.0))[:3]
        n_hat = g[:3, :3] @ wafer_pose(wafers_hat[w])[:3, 2]
        n_true = wt[:3, 2]
        ce = c_hat - wt[:3, 3]
        centre_err.append(float(np.linalg.norm(ce)))
        tilt_err.append(math.degrees(math.acos(max(-1.0, min(1.0, float(n_hat @ n_true))))))
        if wafer_std is not None:
            s = wafer_std[w]
            # Centre in the gauge-aligned frame: compare per axis with the (unrotated) std; the
            # gauge rotation is a fraction of a degree, well inside the tolerance of this check.
            centre_ok &= bool(np.all(np.abs(ce) <= 3.0 * s[:3] + 1e-12))
            wt_par = wafer_params_of(np.linalg.inv(g) @ wt)
            tilt_ok &= bool(np.all(np.abs(wafers_hat[w, 3:] - wt_par[3:]) <= 3.0 * s[3:] + 1e-12))
    errs["wafer_center_mm"] = float(max(centre_err) * 1e3) if centre_err else 0.0
    errs["wafer_tilt_deg"] = float(max(tilt_err)) if tilt_err else 0.0
    sig: dict[str, bool] = {}
    if base_std is not None and offsets_std is not None:
        # Base error in the estimate's tangent [ω; ρ] (body frame of the gauge-aligned estimate).
        r_al = base_al[:3, :3]
        e_body = np.concatenate([-d_rot, r_al.T @ (base_true[:3, 3] - base_al[:3, 3])])
        s = np.asarray(base_std)
        sig["base_rotation"] = bool(np.all(np.abs(e_body[:2]) <= 3.0 * np.sqrt(s[:2] ** 2) + 1e-12))
        sig["base_translation"] = bool(np.all(np.abs(e_body[3:]) <= 3.0 * s[3:] + 1e-12))
        sig["joint_offsets"] = bool(np.all(np.abs(offsets_hat[est_idx] - delta[est_idx]) <= 3.0 * offsets_std[est_idx]))
        sig["wafer_centers"] = centre_ok
        sig["wafer_tilts"] = tilt_ok
    return errs, sig
