"""Times py4dgeo 1.2's classic M3C2 on the files benches/compare.rs and run.py use.

usage: python m3c2_py4dgeo.py DIR [RADIUS] [MAX_DISTANCE]
DIR holds reference.ply, scan.ply (moved back with truth.json's scan_to_reference) as written
by `polishbot synth`; core points are reference[::stride] for 20k and 100k points, normals the
reference's (outward), exactly as the Rust bench and benches/peers/polishbot_m3c2.rs pick them.
2 threads. `m3c2` is what benches/peers/run.py calls.
"""
import json
import sys
import time

import numpy as np
import open3d as o3d
import py4dgeo


def m3c2(d, counts=(20_000, 100_000), radius=0.6, max_distance=1.0, repeats=3):
    """{count: (best seconds with k-d trees, distances)}; loading is not timed."""
    py4dgeo.set_num_threads(2)
    ref = o3d.io.read_point_cloud(d + "/reference.ply")
    R, N = np.asarray(ref.points), np.asarray(ref.normals)
    S = np.asarray(o3d.io.read_point_cloud(d + "/scan.ply").points)
    M = np.array(json.load(open(d + "/truth.json"))["scan_to_reference"])
    S = S @ M[:3, :3].T + M[:3, 3]
    out = {}
    for count in counts:
        stride = len(R) // count
        core, normals = R[::stride][:count].copy(), N[::stride][:count].copy()
        best = float("inf")
        for _ in range(repeats):
            e1, e2 = py4dgeo.Epoch(R), py4dgeo.Epoch(S)
            t = time.perf_counter()
            e1.build_kdtree()
            e2.build_kdtree()
            m = py4dgeo.M3C2(epochs=(e1, e2), corepoints=core, cyl_radius=radius,
                             normal_radii=[radius], max_distance=max_distance,
                             corepoint_normals=normals)
            distances, _ = m.run()
            best = min(best, time.perf_counter() - t)
        out[count] = (best, distances)
    return out


if __name__ == "__main__":
    radius = float(sys.argv[2]) if len(sys.argv) > 2 else 0.6
    max_distance = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
    for count, (best, _) in m3c2(sys.argv[1], radius=radius, max_distance=max_distance).items():
        print(f"py4dgeo classic {count} core points: {best * 1000:.0f} ms (best of 3, with k-d trees)")
