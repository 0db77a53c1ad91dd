"""Coloured point-cloud segmentation: autoteach versus PCL's RegionGrowingRGB on identical clouds.

The cloud is the simulated hallway at the Hokuyo's native 1/4 deg (1081 beams x 140 planes =
151 340 points, the seed's 151 201-point figure), coloured with the simulator's camera colours.
Prints:

- autoteach ``segment_cloud`` (scan mesh, normals estimated, both criteria): median wall time over
  ``--repeats`` runs, adapted Rand error against the ground truth;
- scaling from 1e4 to 1e6 points (whole scans tiled side by side; time per point), and the peak
  resident memory of a fresh process per size (bytes per point);
- PCL 1.13 ``pcl::RegionGrowingRGB`` (k-d tree search, its own colour thresholds) through a small
  C++ driver compiled here against Debian's ``libpcl-dev``: each configuration of a small grid
  around the tutorial's values, its time and adapted Rand error; the best (lowest error) is the
  one compared. PCL gets the unorganised cloud (every valid point) as a binary PLY.

    python benchmarks/segment_peers.py [--repeats 5] [--no-pcl] [--pcl-grid 0,3] [--json]

Times are reported as wall and CPU time (both single-threaded); on a shared machine the CPU
time is the fairer ratio.

Run with RAYON_NUM_THREADS=1 (autoteach's segmentation is single-threaded anyway).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from autoteach import segment

PCL_DRIVER = r"""
#include <chrono>
#include <cstdio>
#include <ctime>
#include <cstdlib>
#include <vector>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/region_growing_rgb.h>
int main(int argc, char** argv) {
  if (argc < 7) { std::fprintf(stderr, "usage: rg in.ply dist point_color region_color min_size out.bin\n"); return 2; }
  pcl::PointCloud<pcl::PointXYZRGB>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZRGB>);
  if (pcl::io::loadPLYFile(argv[1], *cloud) < 0) return 1;
  auto t0 = std::chrono::steady_clock::now();
  std::clock_t c0 = std::clock();
  pcl::search::Search<pcl::PointXYZRGB>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZRGB>);
  pcl::RegionGrowingRGB<pcl::PointXYZRGB> reg;
  reg.setInputCloud(cloud);
  reg.setSearchMethod(tree);
  reg.setDistanceThreshold(std::atof(argv[2]));
  reg.setPointColorThreshold(std::atof(argv[3]));
  reg.setRegionColorThreshold(std::atof(argv[4]));
  reg.setMinClusterSize(std::atoi(argv[5]));
  std::vector<pcl::PointIndices> clusters;
  reg.extract(clusters);
  auto t1 = std::chrono::steady_clock::now();
  std::clock_t c1 = std::clock();
  std::vector<int> labels(cloud->size(), -1);
  for (size_t c = 0; c < clusters.size(); ++c)
    for (int i : clusters[c].indices) labels[i] = (int)c;
  FILE* f = std::fopen(argv[6], "wb");
  std::fwrite(labels.data(), sizeof(int), labels.size(), f);
  std::fclose(f);
  std::printf("%zu %zu %.6f %.6f\n", cloud->size(), clusters.size(), std::chrono::duration<double>(t1 - t0).count(),
              double(c1 - c0) / CLOCKS_PER_SEC);
  return 0;
}
"""

# PCL's tutorial uses distance 10, point colour 6, region colour 5, min size 600 (for its own
# cloud in millimetres-ish units); a grid around metre-scale equivalents.
PCL_GRID = [
    (0.05, 6.0, 5.0, 100),
    (0.05, 10.0, 8.0, 100),
    (0.1, 6.0, 5.0, 100),
    (0.1, 10.0, 8.0, 100),
    (0.1, 15.0, 12.0, 100),
]


def hallway_cloud(seed: int = 1) -> segment.SimulatedScan:
    """The native-resolution hallway scan (151 340 points)."""
    return segment.simulate_scan(
        "hallway",
        beam_step_deg=0.25,
        tilt_start_deg=-19.5,
        tilt_end_deg=50.0,
        tilt_speed_deg_s=20.0,
        seed=seed,
        render=False,
    )


def tiled(sim: segment.SimulatedScan, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An organised cloud of about ``n`` points: copies of the scan side by side (12 m apart)."""
    pts, cols = sim.points, sim.true_colors
    lines, beams = pts.shape[:2]
    need_lines = max(1, round(n / beams))
    reps = -(-need_lines // lines)
    out_p = np.concatenate([pts + np.array([12.0 * r, 0, 0]) for r in range(reps)], axis=0)[:need_lines]
    out_c = np.concatenate([cols] * reps, axis=0)[:need_lines]
    return np.ascontiguousarray(out_p), np.ascontiguousarray(out_c)


def time_ours(points: np.ndarray, colors: np.ndarray, repeats: int) -> tuple[float, float, segment.CloudSegmentation]:
    """Median wall and CPU seconds of ``segment_cloud`` over ``repeats`` runs, and the last result."""
    walls, cpus = [], []
    res = None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        res = segment.segment_cloud(points, colors)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    assert res is not None
    return statistics.median(walls), statistics.median(cpus), res


def peak_rss_bytes(n: int) -> tuple[int, int]:
    """Peak-RSS growth of a fresh process that loads a saved cloud and segments it once.

    The cloud is written to ``.npy`` files first; the fresh process loads them, resets its peak
    resident size to the current one (Linux ``/proc/self/clear_refs``), segments, and reports
    the peak minus the resident size before: what segmentation adds, inputs and outputs included.
    """
    p, c = tiled(hallway_cloud(), n)
    with tempfile.TemporaryDirectory() as tmp:
        np.save(Path(tmp) / "p.npy", p)
        np.save(Path(tmp) / "c.npy", c)
        code = (
            "import sys, numpy as np\n"
            "from autoteach import segment\n"
            f"p = np.load({str(Path(tmp) / 'p.npy')!r}); c = np.load({str(Path(tmp) / 'c.npy')!r})\n"
            "def status(key):\n"
            "    for line in open('/proc/self/status'):\n"
            "        if line.startswith(key):\n"
            "            return int(line.split()[1]) * 1024\n"
            "open('/proc/self/clear_refs', 'w').write('5')  # reset the peak (VmHWM) to the current RSS\n"
            "base = status('VmRSS:')\n"
            "segment.segment_cloud(p, c)\n"
            "print(int(np.isfinite(p[..., 0]).sum()), status('VmHWM:') - base)\n"
        )
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    valid, extra = out.stdout.split()
    return int(valid), int(extra)


def build_pcl(workdir: Path) -> Path | None:
    """Compile the RegionGrowingRGB driver; None (with the reason printed) if PCL is missing."""
    inc = Path("/usr/include/pcl-1.13")
    if shutil.which("g++") is None or not inc.exists():
        print("PCL not available: needs g++ and Debian's libpcl-dev (apt-get install libpcl-dev)", file=sys.stderr)
        return None
    src = workdir / "rg.cpp"
    src.write_text(PCL_DRIVER)
    exe = workdir / "rg"
    cmd = ["g++", "-O2", "-std=c++17", str(src), "-o", str(exe), f"-I{inc}", "-I/usr/include/eigen3"]
    cmd += ["-lpcl_segmentation", "-lpcl_io", "-lpcl_search", "-lpcl_kdtree", "-lpcl_common", "-lpcl_features"]
    cmd += ["-lpcl_filters", "-lboost_system"]
    subprocess.run(cmd, check=True)
    return exe


def run_pcl(
    exe: Path, ply: Path, cfg: tuple[float, float, float, int], workdir: Path
) -> tuple[np.ndarray, float, float]:
    """PCL's labels (-1: unclustered), wall seconds and CPU seconds of ``extract``."""
    out = workdir / "labels.bin"
    res = subprocess.run([str(exe), str(ply), *(str(v) for v in cfg), str(out)], capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"PCL driver failed: {res.stderr}")
    _, _, wall, cpu = res.stdout.split()
    return np.fromfile(out, dtype=np.int32).astype(np.int64), float(wall), float(cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-pcl", action="store_true")
    parser.add_argument(
        "--pcl-grid",
        default=",".join(str(i) for i in range(len(PCL_GRID))),
        help="comma-separated indices into PCL_GRID to run (PCL takes minutes per configuration)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    out: dict[str, object] = {"rayon_threads": os.environ.get("RAYON_NUM_THREADS", "default")}

    sim = hallway_cloud()
    points, colors = sim.points, sim.true_colors
    valid = ~np.isnan(points).any(axis=-1)
    median, cpu, res = time_ours(points, colors, args.repeats)
    keep = valid & (sim.labels >= 0)
    are = segment.adapted_rand_error(sim.labels[keep], res.labels[keep])
    out["autoteach"] = {
        "points": int(valid.sum()),
        "median_s": median,
        "median_cpu_s": cpu,
        "segments": res.num_segments,
        "adapted_rand_error": are,
    }
    print(
        f"autoteach segment_cloud: {valid.sum()} points, {median * 1e3:.1f} ms median ({cpu * 1e3:.1f} ms CPU), "
        f"{res.num_segments} segments, "
        f"adapted Rand error {are:.4f}"
    )

    scaling = []
    for n in (10_000, 100_000, 1_000_000):
        p, c = tiled(sim, n)
        t, tc, _ = time_ours(p, c, max(3, args.repeats if n < 1_000_000 else 3))
        nv = int((~np.isnan(p).any(axis=-1)).sum())
        v, extra = peak_rss_bytes(n)
        scaling.append(
            {
                "points": nv,
                "median_s": t,
                "median_cpu_s": tc,
                "ns_per_point": t / nv * 1e9,
                "cpu_ns_per_point": tc / nv * 1e9,
                "extra_rss_bytes_per_point": extra / v,
            }
        )
        print(
            f"  scaling {nv:>9} points: {t * 1e3:8.1f} ms ({tc * 1e3:8.1f} ms CPU), {t / nv * 1e9:6.0f} ns/point "
            f"({tc / nv * 1e9:6.0f} CPU), peak RSS +{extra / v:.0f} B/point",
            flush=True,
        )
    out["scaling"] = scaling
    out["scaling_ratio_1e6_vs_1e4"] = scaling[-1]["ns_per_point"] / scaling[0]["ns_per_point"]
    out["scaling_ratio_1e6_vs_1e4_cpu"] = scaling[-1]["cpu_ns_per_point"] / scaling[0]["cpu_ns_per_point"]
    print(
        f"  time per point at 1e6 / at 1e4: {out['scaling_ratio_1e6_vs_1e4']:.2f} wall, "
        f"{out['scaling_ratio_1e6_vs_1e4_cpu']:.2f} CPU"
    )

    if not args.no_pcl:
        with tempfile.TemporaryDirectory() as tmp:
            workdir = Path(tmp)
            exe = build_pcl(workdir)
            if exe is not None:
                ply = workdir / "cloud.ply"
                segment.write_ply(ply, points[valid], colors[valid])
                truth = sim.labels[valid]
                runs = []
                for cfg in (PCL_GRID[int(i)] for i in args.pcl_grid.split(",")):
                    labels, seconds, cpu_s = run_pcl(exe, ply, cfg, workdir)
                    # Points PCL leaves unclustered become singletons.
                    un = labels < 0
                    labels[un] = labels.max() + 1 + np.arange(un.sum())
                    err = segment.adapted_rand_error(truth, labels)
                    runs.append({"config": cfg, "seconds": seconds, "cpu_s": cpu_s, "adapted_rand_error": err})
                    print(
                        f"  PCL RegionGrowingRGB {cfg}: {seconds:.2f} s ({cpu_s:.2f} s CPU), "
                        f"adapted Rand error {err:.4f}",
                        flush=True,
                    )
                best = min(runs, key=lambda r: r["adapted_rand_error"])
                out["pcl"] = {
                    "runs": runs,
                    "best": best,
                    "speedup_wall": best["seconds"] / median,
                    "speedup_cpu": best["cpu_s"] / cpu,
                }
                print(
                    f"PCL best {best['config']}: {best['seconds']:.2f} s ({best['cpu_s']:.2f} s CPU), error "
                    f"{best['adapted_rand_error']:.4f}; autoteach is {best['seconds'] / median:.0f}x faster by wall "
                    f"time, {best['cpu_s'] / cpu:.0f}x by CPU time"
                )
    if args.json:
        print(json.dumps(out))


if __name__ == "__main__":
    main()
