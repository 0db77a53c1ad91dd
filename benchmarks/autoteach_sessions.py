"""Auto-teaching on several simulated sessions: errors vs ground truth (Table 5.1), both front ends.

Usage::

    python benchmarks/autoteach_sessions.py [--seeds 0 1 2 3 4] [--frames 200]
        [--frontend simulated|detect|both] [--json]

Each seed simulates a session (12 wafers in slots 4–25, the top one tilted by 1°, joint zero
offsets of 0.2–1°, drifting visual odometry). Front ends:

* ``simulated``: the ground-truth visible rims with 0.3 px Gaussian edge noise and ground-truth
  association (images are not rendered);
* ``detect``: the rendered images through ``detect_wafers`` on every frame, ``WaferTracker`` for
  identities, slots from the nominal chain and gating of every detection by the projected prior
  (the real pipeline, the default of ``autoteach demo`` and ``autoteach run``).

For each it runs :func:`autoteach.pipeline.autoteach` with the conic factor of
000_3b1454b2b2194811.txt eq. (5.13) and with the point-reprojection + nearest-point association
baseline on identical edge points, and prints one row per seed, front end and method (like
Table 5.1), whether every estimate lies inside its 3σ, the frames/rims used, and the goals.
"""

from __future__ import annotations

import argparse
import json
import time

from autoteach.pipeline import autoteach
from autoteach.report import GOALS
from autoteach.sim import simulate_session


def main() -> None:
    """Run the sessions and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--frontend", choices=("simulated", "detect", "both"), default="simulated")
    ap.add_argument("--no-baseline", dest="baseline", action="store_false")
    ap.add_argument("--json", action="store_true")
    ap.add_argument(
        "--no-rim-offset-prior",
        dest="rim_offset_prior",
        action="store_false",
        help="detect front end without the detector's prior on the offset between a wafer's two rims",
    )
    ap.add_argument(
        "--bias",
        action="store_true",
        help="instead: signed normal offset of the detected edge points from the true rims",
    )
    ap.add_argument(
        "--noise-model",
        action="store_true",
        help="instead: RMS edge-point offset from the true rims per rim and predicted band width "
        "(the table behind pipeline.BAND_NOISE_UPPER/LOWER)",
    )
    ap.add_argument(
        "--ukf",
        action="store_true",
        help="instead: UKF diagnosis (exact / white-noise / drifting odometry, noise scaled by 1, 0.1, 0.01)",
    )
    args = ap.parse_args()
    if args.ukf:
        ukf_diagnosis(args.seeds, args.frames)
        return
    if args.bias:
        edge_bias(args.seeds, args.frames, args.rim_offset_prior)
        return
    if args.noise_model:
        noise_model(args.seeds, args.frames, args.rim_offset_prior)
        return
    fronts = ("simulated", "detect") if args.frontend == "both" else (args.frontend,)
    rows = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        session = simulate_session(seed=seed, frames=args.frames, render="detect" in fronts)
        sim_s = time.perf_counter() - t0
        for front in fronts:
            t0 = time.perf_counter()
            r = autoteach(
                session, frontend=front, seed=seed, baseline=args.baseline, rim_offset_prior=args.rim_offset_prior
            )
            stats = r.frontend_stats.get("gated", {})
            rows.append(
                {
                    "seed": seed,
                    "frontend": front,
                    "conic": r.errors,
                    "within_3sigma": r.within_3sigma,
                    "ukf_joint_offset_deg": r.ukf["errors"]["joint_offset_deg"] if r.ukf else None,
                    "point_baseline": r.baseline["errors"] if r.baseline else None,
                    "conic_s": r.timings["slam_mot_s"],
                    "baseline_s": r.baseline["runtime_s"] if r.baseline else None,
                    "total_s": time.perf_counter() - t0,
                    "simulate_s": sim_s,
                    "rms_px": r.rms_px,
                    "rims_used": r.n_observations,
                    "frames_used": len(set(r.observations["frames"])),
                    "frontend_stats": r.frontend_stats,
                    "edges_rejected": stats.get("edges_rejected"),
                }
            )
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    keys = list(GOALS)
    print("seed  front  method " + "".join(f"{k:>20}" for k in keys) + "   3σ  frames  rims  time[s]")
    print("goal                " + "".join(f"{GOALS[k]:>20g}" for k in keys))
    for row in rows:
        ok = "yes" if all(row["within_3sigma"].values()) else "NO"
        fr = row["frontend"][:5]
        print(
            f"{row['seed']:>4}  {fr:<5}  conic  "
            + "".join(f"{row['conic'][k]:>20.4f}" for k in keys)
            + f"  {ok:>4}  {row['frames_used']:>6}  {row['rims_used']:>4}  {row['total_s']:7.1f}"
        )
        if row["point_baseline"]:
            print(
                f"{row['seed']:>4}  {fr:<5}  point  "
                + "".join(f"{row['point_baseline'][k]:>20.4f}" for k in keys)
                + f"                       {row['baseline_s']:7.1f}"
            )
        fails = [k for k in keys if row["conic"][k] > GOALS[k]]
        outside = [k for k, v in row["within_3sigma"].items() if not v]
        print(
            f"{row['seed']:>4}  {fr:<5}  summary: goals missed {fails or 'none'}; outside 3σ {outside or 'none'}; "
            f"UKF θ1,θ2,θ4 max offset error {row['ukf_joint_offset_deg']:.4f} deg"
        )


def edge_bias(seeds: list[int], frames: int, rim_offset_prior: bool = True) -> None:
    """Signed normal offset (pixels, + outside the ellipse) of detected edge points from the true rims.

    Every edge point of ``detect_wafers`` on the rendered frames is assigned to the nearest true
    rim conic (eq. (5.13) with the simulator's camera and wafer poses, within 2 px); its signed
    Sampson distance is binned by rim (upper/lower), by the predicted width of the wafer's side
    band at the point (:func:`autoteach.pipeline.band_width`) and by the circle angle relative
    to the camera direction (0 = the front of the rim). Prints one summary line per bin.
    """
    import numpy as np

    from autoteach.pipeline import _pinhole_k, band_width, detect_all, detector_options

    rows = []
    for seed in seeds:
        s = simulate_session(seed=seed, frames=frames, render=True)
        k, r, h = _pinhole_k(s.camera), s.config.wafer_radius, s.config.wafer_thickness
        det = detect_all(s.images, **(detector_options(k, r, h, edge_profile="pixel") if rim_offset_prior else {}))
        rims = []
        for t in np.asarray(s.wafer_poses, dtype=np.float64):
            for sign in (0.5, -0.5):
                tr = t.copy()
                tr[:3, 3] += tr[:3, 2] * sign * h
                rims.append(tr)
        rims = np.array(rims)
        c0 = np.diag([1.0, 1.0, -r * r])
        for f, edges in enumerate(det):
            t_co = np.linalg.inv(s.camera_poses[f]) @ rims
            hom = np.einsum("ij,rjk->rik", k, t_co[:, :3, [0, 1, 3]])
            hi = np.linalg.inv(hom)
            conics = np.transpose(hi, (0, 2, 1)) @ c0 @ hi
            cam = np.linalg.inv(rims) @ np.append(s.camera_poses[f][:3, 3], 1.0)  # camera in rim frames
            for e in edges:
                p = np.asarray(e.points, dtype=np.float64).reshape(-1, 2)
                ph = np.column_stack([p, np.ones(len(p))])
                cp = np.einsum("rij,nj->rni", conics, ph)
                d = np.einsum("nj,rnj->rn", ph, cp) / (2.0 * np.hypot(cp[..., 0], cp[..., 1]))
                best = np.argmin(np.abs(d), axis=0)
                for ri in np.unique(best):
                    sel = (best == ri) & (np.abs(d[ri]) < 2.0)
                    if not sel.any():
                        continue
                    q = p[sel]
                    band = band_width(q, hi[ri], t_co[ri ^ 1], conics[ri], k, r)
                    x = ph[sel] @ hi[ri].T
                    phi = np.arctan2(x[:, 1] / x[:, 2], x[:, 0] / x[:, 2])
                    rel = (phi - np.arctan2(cam[ri, 1], cam[ri, 0]) + np.pi) % (2 * np.pi) - np.pi
                    for dd, bb, aa in zip(d[ri][sel], band, rel, strict=True):
                        rows.append((ri % 2, dd, bb, aa))
    a = np.array(rows)
    print(f"edge bias: {len(a)} detected points within 2 px of a true rim, seeds {seeds}, {frames} frames")
    for rim in (0, 1):
        m = a[:, 0] == rim
        name = ("upper", "lower")[rim]
        d = a[m, 1]
        print(f"edge bias {name}: n {m.sum()} mean {d.mean():+.4f} px, std {d.std():.3f} px")
        for lo, hi_ in ((0, 1), (1, 1.5), (1.5, 2), (2, 2.5), (2.5, 3), (3, 4), (4, 99)):
            b = m & (a[:, 2] >= lo) & (a[:, 2] < hi_)
            if b.sum() >= 20:
                print(
                    f"edge bias {name} band {lo}-{hi_} px: n {b.sum():6d} mean {a[b, 1].mean():+.4f} "
                    f"std {a[b, 1].std():.3f}"
                )
        for lo in range(0, 120, 15):
            b = m & (np.abs(np.degrees(a[:, 3])) >= lo) & (np.abs(np.degrees(a[:, 3])) < lo + 15)
            if b.sum() >= 20:
                print(
                    f"edge bias {name} |arc angle from front| {lo}-{lo + 15} deg: n {b.sum():6d} "
                    f"mean {a[b, 1].mean():+.4f} std {a[b, 1].std():.3f}"
                )


def noise_model(seeds: list[int], frames: int, rim_offset_prior: bool = True) -> None:
    """RMS normal offset of the points the pipeline feeds the solver from the true rims, by band width.

    Runs the detect front end without the band filter and without band weights
    (``min_band_px=0``, ``band_weights=False``) and takes the points of the final solve; each
    point's signed Sampson distance to its true rim conic (simulator camera and wafer poses) is
    binned by rim and by the band width predicted from the truth
    (:func:`autoteach.pipeline.band_width`). Prints the RMS per bin and its ratio to the RMS of
    upper-rim points on bands of at least 3 px: the relative noise of
    ``pipeline.BAND_NOISE_UPPER`` / ``BAND_NOISE_LOWER``.
    """
    import numpy as np

    from autoteach.pipeline import _pinhole_k, band_width

    rows = []
    for seed in seeds:
        s = simulate_session(seed=seed, frames=frames, render=True)
        r = autoteach(
            s,
            frontend="detect",
            seed=seed,
            min_band_px=0.0,
            band_weights=False,
            rim_offset_prior=rim_offset_prior,
        )
        k, rad, h = _pinhole_k(s.camera), s.config.wafer_radius, s.config.wafer_thickness
        true_slots = [int(v) for v in s.wafer_slots]
        c0 = np.diag([1.0, 1.0, -rad * rad])
        o = r.observations
        for i, (f, w, rim) in enumerate(zip(o["frames"], o["wafers"], o["rims"], strict=True)):
            slot = int(r.wafer_slots[w])
            if slot not in true_slots:
                continue
            t_wo = np.asarray(s.wafer_poses[true_slots.index(slot)], dtype=np.float64)
            t_cw = np.linalg.inv(s.camera_poses[f])
            rim_t = []
            for kind in (rim, 1 - rim):
                t = t_wo.copy()
                t[:3, 3] += t[:3, 2] * ((0.5 if kind == 0 else -0.5) * h)
                rim_t.append(t_cw @ t)
            hi = np.linalg.inv(k @ rim_t[0][:3, [0, 1, 3]])
            c = hi.T @ c0 @ hi
            t_other = rim_t[1]
            p = o["points"][o["start"][i] : o["start"][i + 1]]
            ph = np.column_stack([p, np.ones(len(p))])
            cp = ph @ c.T
            d = np.einsum("ij,ij->i", ph, cp) / (2.0 * np.hypot(cp[:, 0], cp[:, 1]))
            b = band_width(p, hi, t_other, c, k, rad)
            rows.extend(zip([rim] * len(p), d, b, strict=True))
    a = np.array(rows)
    ref = a[(a[:, 0] == 0) & (a[:, 2] >= 3.0), 1]
    r0 = float(np.sqrt(np.mean(ref**2)))
    print(f"noise model: {len(a)} points, seeds {seeds}; reference RMS (upper rim, band >= 3 px) {r0:.4f} px")
    edges = (0.0, 1.0, 1.5, 2.0, 2.25, 2.5, 2.75, 3.0, 3.25, 3.5, 4.0, 99.0)
    for rim in (0, 1):
        for lo, hi_ in zip(edges[:-1], edges[1:], strict=True):
            m = (a[:, 0] == rim) & (a[:, 2] >= lo) & (a[:, 2] < hi_)
            if m.sum() >= 50:
                rms = float(np.sqrt(np.mean(a[m, 1] ** 2)))
                print(
                    f"noise model {('upper', 'lower')[rim]} band {lo:.2f}-{hi_:.2f} px: n {m.sum():6d} "
                    f"mean {a[m, 1].mean():+.4f} rms {rms:.4f} ratio {rms / r0:.2f}"
                )


def ukf_diagnosis(seeds: list[int], frames: int) -> None:
    """UKF offsets (θ1, θ2, θ4) against their Cramér–Rao bound and the batch estimate (eqs. (5.1)–(5.2)).

    For each seed and trajectory (the default session and a teaching motion that turns the arm:
    yaw ±30°, x 25 cm, y ±30 cm) and each odometry — the simulator's drifting visual odometry
    (world-frame increments, :func:`autoteach.sim.simulate_odometry`) and a SLAM with a map
    (relative poses, :func:`autoteach.sim.odometry.simulate_slam`) — prints the bound
    (:func:`~autoteach.sim.odometry.offset_information`), the batch generalised-least-squares
    estimate over the whole session (:func:`~autoteach.sim.odometry.batch_offsets`: the best any
    filter can do) and the UKF's final offsets and σ, with the noise matched to the odometry and
    (drifting odometry) with the seed's eq. (5.2) noise.
    """
    import math

    import numpy as np

    from autoteach import _core
    from autoteach.geometry import WaferRobot
    from autoteach.pipeline import _robot_array
    from autoteach.sim import SimConfig, TrajectoryConfig
    from autoteach.sim.odometry import (
        OdometryConfig,
        SlamConfig,
        batch_offsets,
        offset_information,
        simulate_odometry,
        simulate_slam,
    )

    teach = TrajectoryConfig(yaw_max=math.radians(30.0), x_range=(-0.60, -0.35), y_range=(-0.15, 0.15))
    fmt = lambda v: "[" + " ".join(f"{x:7.4f}" if math.isfinite(x) else "    n/a" for x in v) + "]"  # noqa: E731
    worst: dict[str, float] = {}
    for traj_name, cfg in (("default", SimConfig()), ("teach", SimConfig(trajectory=teach))):
        for seed in seeds:
            s = simulate_session(seed=seed, frames=frames, render=False, config=cfg)
            robot_arr, base = _robot_array(s.config.robot), np.array(s.config.base_pose)
            robot = WaferRobot(params=s.config.robot, base=base)
            enc = np.ascontiguousarray(s.joints_encoder)
            sn = np.array(s.config.encoder_noise)
            true = np.asarray(s.calibration.joint_offsets)[[0, 1, 3]]
            slam = SlamConfig()
            vo = OdometryConfig()
            cases = [
                ("VO drift, matched", simulate_odometry(s.camera_poses, seed), vo, "world", vo.ukf_noise(), None),
                ("VO drift, eq.(5.2)", simulate_odometry(s.camera_poses, seed), vo, "world", None, None),
                ("SLAM map", simulate_slam(s.camera_poses, seed, slam), slam, "camera", slam.ukf_noise(sn), slam),
            ]
            for name, inc, ocfg, frame, noise, slam_cfg in cases:
                t0 = time.perf_counter()
                info = offset_information(robot, enc, true, ocfg, sn, frame)
                est, _, bad = batch_offsets(robot, enc, inc, ocfg, sn, frame)
                t_batch = time.perf_counter() - t0
                t0 = time.perf_counter()
                r = _core.handeye_ukf(
                    robot_arr,
                    base,
                    enc,
                    np.ascontiguousarray(inc),
                    noise,
                    odometry=None if slam_cfg is None else slam_cfg.ukf_odometry(),
                )
                t_ukf = time.perf_counter() - t0
                crb = np.degrees(info.crb_std)
                ok = np.isfinite(crb)
                e_b = np.where(ok, np.degrees(est - true), math.nan)
                e_u = np.where(ok, np.degrees(np.asarray(r["offsets"])[-1] - true), math.nan)
                sd_u = np.degrees(np.asarray(r["offset_std"])[-1])
                key = f"{traj_name} / {name}"
                worst[key] = max(worst.get(key, 0.0), float(np.nanmax(np.abs(e_u))))
                worst[key + " CRB"] = max(worst.get(key + " CRB", 0.0), float(np.max(crb[ok])))
                print(
                    f"seed {seed} {traj_name:<7} {name:<19} CRB {fmt(crb)} batch err {fmt(e_b)} "
                    f"UKF err {fmt(e_u)} σ {fmt(np.where(ok, sd_u, math.nan))} "
                    f"max|e|/σ {np.nanmax(np.abs(e_u) / sd_u):.2f} unobservable {list(bad) or '-'} "
                    f"[batch {t_batch:.1f} s, UKF {t_ukf * 1e3:.0f} ms]",
                    flush=True,
                )
    for key in sorted(k for k in worst if not k.endswith(" CRB")):
        print(
            f"summary UKF {key}: worst offset error {worst[key]:.4f} deg, worst CRB {worst[key + ' CRB']:.4f} deg "
            f"(seeds {seeds}, {frames} frames; observable offsets only)"
        )


if __name__ == "__main__":
    main()
