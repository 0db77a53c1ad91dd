"""Linear assignment: autoteach vs ``scipy.optimize.linear_sum_assignment`` and ``lap.lapjv``.

Square n × n costs for n = 200, 1 000, 3 000 in three families, the same array (C-contiguous
float64) given to every solver: ``uniform`` (U[0, 1)), ``integer`` (integers in [0, 1 000), many
ties) and ``geometric`` (Euclidean distances between two uniform point sets in the unit
square, the structure of track association). Accuracy is the total cost of the returned
assignment; ours must equal the peer's (both optimal) to 1e-9 relative.
"""

from __future__ import annotations

import numpy as np

from peer_rows import median_time, missing, missing_row, row


def costs(family: str, n: int, seed: int = 0) -> np.ndarray:
    """An n × n cost matrix of the family (deterministic for the seed)."""
    rng = np.random.default_rng(seed)
    if family == "uniform":
        return rng.random((n, n))
    if family == "integer":
        return rng.integers(0, 1000, size=(n, n)).astype(np.float64)
    if family == "geometric":
        a, b = rng.random((n, 2)), rng.random((n, 2))
        return np.ascontiguousarray(np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2))
    raise ValueError(family)


def repeats_for(n: int, quick: bool) -> int:
    """Repeats per solver: more for the small, fast problems."""
    if quick:
        return 3
    return 21 if n <= 200 else (5 if n <= 1000 else 3)


def rows(threads: int, quick: bool) -> list[dict]:
    """One row per (family, size, peer)."""
    from scipy.optimize import linear_sum_assignment as scipy_lsa

    from autoteach.detect import linear_sum_assignment as ours_lsa

    lapjv = None
    if not missing("lap"):
        import lap

        lapjv = lap.lapjv

    sizes = (200, 1000) if quick else (200, 1000, 3000)
    out = []
    for n in sizes:
        for family in ("uniform", "integer", "geometric"):
            c = costs(family, n)
            reps = repeats_for(n, quick)
            workload = f"assignment {n}×{n}, {family}"
            t_ours, (r, k) = median_time(lambda c=c: ours_lsa(c), reps)
            ours_cost = float(c[r, k].sum())
            t_sp, (rs, ks) = median_time(lambda c=c: scipy_lsa(c), reps)
            sp_cost = float(c[rs, ks].sum())
            peers = [("scipy.optimize.linear_sum_assignment", t_sp, sp_cost)]
            if lapjv is None:
                out.append(missing_row(workload, "lap.lapjv", ["lap"]))
            else:
                t_lap, (_, x, _) = median_time(lambda c=c: lapjv(c, extend_cost=False, return_cost=True), reps)
                peers.append(("lap.lapjv (dense, extend_cost=False)", t_lap, float(c[np.arange(n), x].sum())))
            for name, t_peer, peer_cost in peers:
                rel = abs(ours_cost - peer_cost) / max(1.0, abs(peer_cost))
                verdict = "same" if rel < 1e-9 else ("better" if ours_cost < peer_cost else "WORSE")
                out.append(
                    row(
                        workload,
                        name,
                        t_peer,
                        t_ours,
                        f"cost {peer_cost:.6g}",
                        f"{verdict} (rel. diff {rel:.0e})",
                        f"median of {reps}",
                    )
                )
    return out
