"""Times Open3D's remove_statistical_outlier on the PLY files the preprocess bench writes.

Usage: OMP_NUM_THREADS=2 python benches/peers/sor.py [DIR]   (DIR: $POLISHBOT_BENCH_DATA or
<tmp>/polishbot-bench). Prints one line per file: points, kept, best and median wall and CPU seconds.
"""
import os
import statistics
import sys
import tempfile
import time

import numpy as np
import open3d as o3d

directory = sys.argv[1] if len(sys.argv) > 1 else os.environ.get(
    "POLISHBOT_BENCH_DATA", os.path.join(tempfile.gettempdir(), "polishbot-bench"))
for name in ["sor_300k.ply", "sor_1000k.ply"]:
    path = os.path.join(directory, name)
    if not os.path.exists(path):
        print(f"{name}: missing (run the preprocess bench first)")
        continue
    pcd = o3d.io.read_point_cloud(path)
    times, cpu = [], []
    for _ in range(5):
        t0, c0 = time.perf_counter(), time.process_time()
        _, kept = pcd.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    print(f"{name}: points {len(pcd.points)} kept {len(kept)}: wall best {min(times):.3f} s "
          f"median {statistics.median(times):.3f} s; cpu (all threads) best {min(cpu):.3f} s "
          f"median {statistics.median(cpu):.3f} s")
