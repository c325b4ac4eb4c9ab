"""Times Open3D's remove_statistical_outlier (k 20, std ratio 2.0) on PLY files.

Usage: OMP_NUM_THREADS=2 python benches/peers/sor.py [DIR | FILE.ply ...]
  DIR (default $POLISHBOT_BENCH_DATA or <tmp>/polishbot-bench) holds sor_300k.ply and
  sor_1000k.ply as the preprocess bench writes them. Prints one line per file: points, kept,
  best and median wall and CPU seconds. `time_sor` is what benches/peers/run.py calls.
"""
import os
import statistics
import sys
import tempfile
import time

import numpy as np
import open3d as o3d


def time_sor(path, repeats=5):
    """Best and median wall / CPU seconds of `repeats` filter runs (loading not timed), the
    points, and the kept count and indices."""
    pcd = o3d.io.read_point_cloud(path)
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        _, kept = pcd.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"points": len(pcd.points), "kept": len(kept), "kept_indices": kept, "best": min(times),
            "median": statistics.median(times), "cpu_best": min(cpu),
            "cpu_median": statistics.median(cpu)}


def main(args):
    if args and all(a.endswith(".ply") for a in args):
        paths = args
    else:
        directory = args[0] if args else os.environ.get(
            "POLISHBOT_BENCH_DATA", os.path.join(tempfile.gettempdir(), "polishbot-bench"))
        paths = [os.path.join(directory, n) for n in ["sor_300k.ply", "sor_1000k.ply"]]
    for path in paths:
        name = os.path.basename(path)
        if not os.path.exists(path):
            print(f"{name}: missing (run the preprocess bench first)")
            continue
        r = time_sor(path)
        print(f"{name}: points {r['points']} kept {r['kept']}: wall best {r['best']:.3f} s "
              f"median {r['median']:.3f} s; cpu (all threads) best {r['cpu_best']:.3f} s "
              f"median {r['cpu_median']:.3f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
