"""small_gicp 1.0's GICP (PyPI small-gicp) as the fine registration peer.

Usage: register_small_gicp.py REFERENCE SCAN VOXEL INIT_JSON [TRUTH_JSON]
  small_gicp has no global (coarse) stage, so it starts from the pose `scan_to_reference` of
  INIT_JSON (benches/peers/run.py gives it polishbot's coarse MAC pose,
  registration.json's `coarse.scan_to_reference`): voxel down-sampling at VOXEL, covariances,
  k-d trees and GICP (correspondences within 2 VOXEL, up to 30 iterations, stopping when the
  update is under 1e-4 rad and 1e-4 mm), 2 threads.
Prints one JSON object: seconds (loading not timed), the pose, iterations, inliers and, with
TRUTH_JSON, the rotation (deg) and translation (mm) errors. `register` is what run.py calls.
"""
import json
import sys
import time

import numpy as np
import open3d as o3d
import small_gicp

from register_open3d import pose_error


def register(ref_path, scan_path, voxel, init_pose, truth_path=None):
    target = np.asarray(o3d.io.read_point_cloud(ref_path).points)
    source = np.asarray(o3d.io.read_point_cloud(scan_path).points)
    t = time.perf_counter()
    result = small_gicp.align(target, source, np.asarray(init_pose), registration_type="GICP",
                              downsampling_resolution=voxel,
                              max_correspondence_distance=2 * voxel, num_threads=2,
                              max_iterations=30, rotation_epsilon=1e-4,
                              translation_epsilon=1e-4)
    seconds = time.perf_counter() - t
    out = {"seconds": seconds, "scan_to_reference": result.T_target_source.tolist(),
           "converged": bool(result.converged), "iterations": int(result.iterations),
           "inliers": int(result.num_inliers)}
    if truth_path:
        truth = np.array(json.load(open(truth_path))["scan_to_reference"])
        out["initial_error_deg_mm"] = pose_error(init_pose, truth)
        out["error_deg_mm"] = pose_error(result.T_target_source, truth)
    return out


def main():
    init = json.load(open(sys.argv[4]))["scan_to_reference"]
    truth = sys.argv[5] if len(sys.argv) > 5 else None
    print(json.dumps(register(sys.argv[1], sys.argv[2], float(sys.argv[3]), init, truth)))


if __name__ == "__main__":
    main()
