"""Open3D's global registration tutorial pipeline on the files polishbot registers.

Usage: register_open3d.py REFERENCE SCAN VOXEL [TRUTH_JSON]
  voxel down-sampling, normals (radius 2 voxel, 30 nn), FPFH (radius 5 voxel, 100 nn),
  RANSAC on feature matches (mutual filter, distance 1.5 voxel, 3 points, edge length 0.9,
  100,000 iterations, confidence 0.999), then point-to-plane ICP on the full clouds
  (distance 0.4 voxel), all as in the tutorial. The target (reference) gets normals from its
  file, or estimated like the tutorial when it has none.
Prints one JSON object: times per step (s), the pose (scan_to_reference, row-major), fitness,
inlier RMSE and, with TRUTH_JSON, the rotation (deg) and translation (mm) errors.
`register` is what benches/peers/run.py calls.
"""
import json
import sys
import time

import numpy as np
import open3d as o3d

reg = o3d.pipelines.registration


def pose_error(a, b):
    """Rotation (deg) and translation (mm) between two 4x4 poses."""
    a, b = np.asarray(a), np.asarray(b)
    d = np.linalg.inv(a) @ b
    angle = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
    return float(angle), float(np.linalg.norm(a[:3, 3] - b[:3, 3]))


def register(ref_path, scan_path, voxel, truth_path=None):
    """Runs the pipeline; returns the dict main prints (loading is not timed)."""
    target = o3d.io.read_point_cloud(ref_path)
    source = o3d.io.read_point_cloud(scan_path)
    times = {}
    t0 = time.perf_counter()

    def prep(pcd):
        down = pcd.voxel_down_sample(voxel)
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
        fpfh = reg.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        return down, fpfh

    t = time.perf_counter()
    src_down, src_fpfh = prep(source)
    tgt_down, tgt_fpfh = prep(target)
    times["prepare_and_fpfh"] = time.perf_counter() - t

    t = time.perf_counter()
    dist = 1.5 * voxel
    ransac = reg.registration_ransac_based_on_feature_matching(
        src_down, tgt_down, src_fpfh, tgt_fpfh, True, dist,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(dist)],
        reg.RANSACConvergenceCriteria(100000, 0.999))
    times["ransac"] = time.perf_counter() - t

    t = time.perf_counter()
    if not target.has_normals():
        target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    icp = reg.registration_icp(source, target, 0.4 * voxel, ransac.transformation,
                               reg.TransformationEstimationPointToPlane())
    times["icp"] = time.perf_counter() - t
    times["total"] = time.perf_counter() - t0

    out = {
        "times": times,
        "scan_to_reference": icp.transformation.tolist(),
        "coarse_scan_to_reference": ransac.transformation.tolist(),
        "fitness": icp.fitness,
        "inlier_rmse": icp.inlier_rmse,
        "scan_points_down": len(src_down.points),
        "reference_points_down": len(tgt_down.points),
    }
    if truth_path:
        truth = np.array(json.load(open(truth_path))["scan_to_reference"])
        out["coarse_error_deg_mm"] = pose_error(ransac.transformation, truth)
        out["error_deg_mm"] = pose_error(icp.transformation, truth)
    return out


def main():
    truth = sys.argv[4] if len(sys.argv) > 4 else None
    print(json.dumps(register(sys.argv[1], sys.argv[2], float(sys.argv[3]), truth)))


if __name__ == "__main__":
    main()
