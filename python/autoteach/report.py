"""Report folder of an auto-teaching run: summary JSON, table and plots (matplotlib, optional).

Plots (000_3b1454b2b2194811.txt ch. 5):

* ``trajectories.png`` — bird's-eye view of the camera trajectory from the encoders (uncalibrated
  forward kinematics), from visual odometry (dead reckoning) and fused by the UKF, with the
  truth when known (like Fig. 5.8);
* ``convergence.png`` — calibration parameters after every sliding window with ±3σ bands
  (like Fig. 5.11);
* ``wafer_stack.png`` — the reconstructed wafer rims in 3D, estimates and truth (like Fig. 5.13);
* ``detections.png`` — edge points used by SLAM-MOT drawn on sample frames with the fitted rim
  conics.

Without matplotlib (``pip install autoteach[plot]``) only the JSON summary and the text table are
written and :func:`write_report` says so in its return value.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from autoteach.pipeline import AutoTeachResult, wafer_pose

GOALS: dict[str, float] = {
    "joint_offset_deg": 0.02,
    "base_translation_mm": 0.2,
    "base_rotation_deg": 0.02,
    "wafer_center_mm": 0.3,
    "wafer_tilt_deg": 0.1,
}


def format_table(result: AutoTeachResult) -> str:
    """Estimates (with 1σ) against ground truth, like Table 5.1, plus the error summary."""
    d = result.to_dict()
    est = d["estimates"]
    lines = ["auto-teaching result (reference frame: lowest wafer; SLAM-MOT with conic factors)"]
    pos = ", ".join(f"{v * 1e3:+9.3f}" for v in est["base_position_m"])
    pstd = ", ".join("  n/a" if s is None else f"{s * 1e3:.3f}" for s in est["base_position_std_m"])
    rpy = ", ".join(f"{v:+.4f}" for v in est["base_rpy_deg"])
    lines.append(f"  base position [mm]: ({pos})  σ ({pstd})")
    lines.append(f"  base roll, pitch, yaw [deg]: ({rpy}) (yaw = gauge)")
    lines.append("  joint zero offsets:")
    for name, e in est["joint_offsets"].items():
        if e["status"] in ("estimated", "ukf"):
            src = "SLAM-MOT" if e["status"] == "estimated" else "UKF"
            std = "n/a" if e["std"] is None else f"{e['std']:.4f}"
            lines.append(f"    {name:<7} {e['value']:+.4f} ± {std} {e['unit']} ({src})")
        else:
            lines.append(f"    {name:<7} {e['status']}")
    lines.append("  wafer  slot   centre x, y, z [mm]            σ [mm]             tilt rx, ry [deg]   res. [px/mm]")
    for i, w in enumerate(est["wafers"]):
        c = (
            ", ".join(f"{v * 1e3:+7.2f}" for v in w["center_m"])
            if all(math.isfinite(v) for v in w["center_m"])
            else "unobserved"
        )
        s = ", ".join("n/a" if v is None else f"{v * 1e3:.3f}" for v in w["center_std_m"])
        t = ", ".join(f"{v:+.3f}" for v in w["tilt_deg"])
        r = ", ".join("n/a" if v is None else f"{v:.2f}" for v in w["resolution_px_per_mm"][:2])
        lines.append(f"  {i:>5}  {w['slot']:>4}   {c:<30} ({s:<20}) {t:<18} {r}")
    if result.unobservable:
        lines.append(f"  unobservable: {result.unobservable}")
    if result.errors:
        lines.append("errors against ground truth (goal; inside 3σ):")
        sig = result.within_3sigma or {}
        keys = {
            "joint_offset_deg": "joint_offsets",
            "base_translation_mm": "base_translation",
            "base_rotation_deg": "base_rotation",
            "wafer_center_mm": "wafer_centers",
            "wafer_tilt_deg": "wafer_tilts",
        }
        for k, v in result.errors.items():
            ok = "yes" if sig.get(keys[k], False) else "NO"
            lines.append(f"  {k:<22} {v:9.4f}   (goal {GOALS[k]:g}; {ok})")
        if result.ukf is not None and "errors" in result.ukf:
            seen = result.ukf.get("observable", [True, True, True])
            names = ", ".join(n for n, o in zip(("θ1", "θ2", "θ4"), seen, strict=True) if o)
            hidden = [n for n, o in zip(("θ1", "θ2", "θ4"), seen, strict=True) if not o]
            note = f"; {', '.join(hidden)} unobservable to the UKF" if hidden else ""
            lines.append(
                f"  UKF joint offsets ({names}) max error: {result.ukf['errors']['joint_offset_deg']:.4f} deg{note}"
            )
        if result.baseline is not None and "errors" in result.baseline:
            b = result.baseline["errors"]
            lines.append(
                "  point-reprojection baseline (nearest-point association): "
                + ", ".join(f"{k} {v:.4f}" for k, v in b.items())
            )
    st = result.frontend_stats
    if st.get("initial"):
        ini, gated = st["initial"], st.get("gated", {})
        lines.append(
            f"front end {result.frontend}: {ini.get('detections', 0)} detected rims, {ini.get('tracks', 0)} tracks "
            f"({ini.get('tracks_used', 0)} consistently tracked and placed in slots {ini.get('slots', [])}); "
            f"after gating by the projected prior ({gated.get('gate_px', 'n/a')} px): "
            f"{gated.get('rims_used', 0)} rims in {gated.get('frames_used', 0)} frames used, "
            f"{gated.get('edges_rejected', 0)} edges rejected"
            + (f"; too few views: slots {gated['wafers_too_few_views']}" if gated.get("wafers_too_few_views") else "")
        )
        if "spurious_slots" in st:
            lines.append(f"  vs ground truth: slots missed {st['true_slots_missed']}, spurious {st['spurious_slots']}")
    lines.append(
        f"edge rms {result.rms_px:.3f} px over {result.n_observations} rim observations; runtime "
        f"{sum(result.timings.values()):.2f} s"
    )
    return "\n".join(lines)


def write_report(result: AutoTeachResult, out: Path, session: Any = None) -> dict[str, Any]:
    """Write ``autoteach.json``, ``autoteach.txt`` and the plots into ``out``; returns the file list."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Any] = {}
    (out / "autoteach.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    files["summary"] = str(out / "autoteach.json")
    (out / "autoteach.txt").write_text(format_table(result) + "\n")
    files["table"] = str(out / "autoteach.txt")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        files["plots"] = "matplotlib is not installed (pip install autoteach[plot]): no plots"
        return files
    plots = []
    for name, fn in (
        ("trajectories.png", _plot_trajectories),
        ("convergence.png", _plot_convergence),
        ("wafer_stack.png", _plot_wafers),
        ("detections.png", _plot_detections),
    ):
        fig = fn(plt, result, session)
        if fig is not None:
            fig.savefig(out / name, dpi=90)
            plt.close(fig)
            plots.append(str(out / name))
    files["plots"] = plots
    return files


def _plot_trajectories(plt: Any, r: AutoTeachResult, session: Any) -> Any:
    if r.ukf is None:
        return None
    fig, ax = plt.subplots(figsize=(6, 5))
    for key, label, style in (
        ("encoder_poses", "encoders (uncalibrated)", "b-"),
        ("odometry_poses", "visual odometry", "r-"),
        ("poses", "UKF fused", "y-"),
    ):
        p = np.asarray(r.ukf[key])
        ax.plot(p[:, 0, 3] * 1e3, p[:, 1, 3] * 1e3, style, label=label, lw=1.5)
    if session is not None and session.camera_poses is not None:
        p = np.asarray(session.camera_poses)
        ax.plot(p[:, 0, 3] * 1e3, p[:, 1, 3] * 1e3, "k--", label="truth", lw=1)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title("camera trajectory, bird's-eye view (Fig. 5.8)")
    ax.axis("equal")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _plot_convergence(plt: Any, r: AutoTeachResult, session: Any) -> Any:
    if not r.history:
        return None
    frames = [h["last_frame"] for h in r.history]
    base = np.stack([np.asarray(h["base_pose"]) for h in r.history])
    std = np.stack([np.asarray(h["std"]) for h in r.history])
    offs = np.stack([np.asarray(h["joint_offsets"]) for h in r.history])
    fig, axes = plt.subplots(2, 2, figsize=(10, 6))
    for i, c in enumerate("xyz"):
        v = (base[:, i, 3] - r.base_pose[i, 3]) * 1e3
        axes[0, 0].plot(frames, v, label=f"t{c}")
        axes[0, 0].fill_between(frames, v - 3e3 * std[:, 3 + i], v + 3e3 * std[:, 3 + i], alpha=0.15)
    axes[0, 0].set_title("base translation − final [mm] (±3σ)")
    axes[0, 0].legend(fontsize=8)
    rp = np.array([[math.atan2(b[2, 1], b[2, 2]), -math.asin(max(-1, min(1, b[2, 0])))] for b in base[:, :3, :3]])
    for i, c in enumerate(("roll", "pitch")):
        axes[0, 1].plot(frames, np.degrees(rp[:, i]), label=c)
    axes[0, 1].set_title("base roll / pitch [deg]")
    axes[0, 1].legend(fontsize=8)
    for j, name in enumerate(("joint1", "joint2", "joint3", "joint4")):
        if r.offset_status[name] == "estimated":
            axes[1, 0].plot(frames, np.degrees(offs[:, j]), label=name)
            if session is not None and session.calibration is not None:
                axes[1, 0].axhline(math.degrees(session.calibration.joint_offsets[j]), ls=":", c="k", lw=0.8)
    axes[1, 0].set_title("joint zero offsets [deg] (dotted: truth)")
    axes[1, 0].legend(fontsize=8)
    if r.ukf is not None:
        o = np.degrees(np.asarray(r.ukf["offsets"]))
        sd = np.degrees(np.asarray(r.ukf["offset_std"])) if "offset_std" in r.ukf else None
        observable = r.ukf.get("observable", [True] * o.shape[1])
        for i, name in enumerate(("joint1", "joint2", "joint4")):
            if not observable[i]:
                continue  # relative motion cannot see it (reported unobservable, not drawn)
            (line,) = axes[1, 1].plot(o[:, i], label=name)
            if sd is not None:
                x = np.arange(len(o))
                lo, hi = o[:, i] - 3.0 * sd[:, i], o[:, i] + 3.0 * sd[:, i]
                axes[1, 1].fill_between(x, lo, hi, color=line.get_color(), alpha=0.15, lw=0)
            if "true_offsets" in r.ukf:
                axes[1, 1].axhline(math.degrees(r.ukf["true_offsets"][i]), ls=":", c="k", lw=0.8)
        axes[1, 1].set_title("UKF joint offsets over frames [deg] (band: ±3σ)")
        axes[1, 1].legend(fontsize=8)
    for ax in axes.flat:
        ax.set_xlabel("frame")
    fig.suptitle("calibration converging over frames (Fig. 5.11)")
    fig.tight_layout()
    return fig


def _rim(pose: np.ndarray, radius: float, z: float) -> np.ndarray:
    th = np.linspace(0, 2 * np.pi, 90)
    pts = np.stack([radius * np.cos(th), radius * np.sin(th), np.full_like(th, z), np.ones_like(th)])
    return (pose @ pts)[:3]


def _plot_wafers(plt: Any, r: AutoTeachResult, session: Any) -> Any:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(111, projection="3d")
    radius = session.config.wafer_radius if session is not None and session.config is not None else 0.15
    for w in r.wafer_params:
        if not np.all(np.isfinite(w)):
            continue
        x = _rim(wafer_pose(w), radius, 0.0) * 1e3
        ax.plot(x[0], x[1], x[2], "b-", lw=1)
    if session is not None and session.wafer_poses is not None:
        ref = int(np.argmin(np.where(r.wafer_slots >= 0, r.wafer_slots, 10**6)))
        t_ref_inv = np.linalg.inv(session.wafer_poses[ref])
        for p in session.wafer_poses:
            x = _rim(t_ref_inv @ p, radius, 0.0) * 1e3
            ax.plot(x[0], x[1], x[2], "r:", lw=0.8)
    cams = np.asarray(r.camera_poses)[:, :3, 3] * 1e3
    ax.plot(cams[:, 0], cams[:, 1], cams[:, 2], "g-", lw=0.8)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.set_title("reconstructed wafer stack (blue), truth (red dotted), camera (green)")
    return fig


def _plot_detections(plt: Any, r: AutoTeachResult, session: Any) -> Any:
    if session is None or session.images is None or not len(r.observations.get("frames", [])):
        return None
    obs = r.observations
    frames = sorted(set(obs["frames"]))
    picks = [frames[int(i)] for i in np.linspace(0, len(frames) - 1, min(4, len(frames)))]
    fig, axes = plt.subplots(1, len(picks), figsize=(4 * len(picks), 3))
    axes = np.atleast_1d(axes)
    for ax, f in zip(axes, picks, strict=True):
        ax.imshow(session.images[f], cmap="gray", vmin=0, vmax=255)
        for i, fi in enumerate(obs["frames"]):
            if fi != f:
                continue
            p = obs["points"][obs["start"][i] : obs["start"][i + 1]]
            ax.plot(p[:, 0], p[:, 1], ".", ms=2)
        ax.set_title(f"frame {f}")
        ax.axis("off")
    fig.suptitle("edge points used by SLAM-MOT")
    fig.tight_layout()
    return fig
