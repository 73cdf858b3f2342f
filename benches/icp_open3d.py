#!/usr/bin/env python3
"""Open3D's point-to-plane ICP on the case written by `examples/icp_compare.rs`.

Usage: icp_open3d.py CASE_DIR  -> one JSON line (errors against the reference, wall time).

The same problem and schedule as rigcal's: the target downsampled to the same voxel with
normals from a 0.5 m neighbourhood (at most 30 neighbours), then for each level (source voxel,
correspondence distance) up to the same number of iterations of point-to-plane ICP with a
Huber kernel of the same width, each level starting from the previous result. Open3D stops a
level on relative fitness and RMSE changes below 1e-6 (rigcal: a step below 1e-6 rad / m).
Timing covers downsampling, normals and ICP; reading the files is excluded, as for rigcal.
"""
import json
import math
import sys
import time

import numpy as np
import open3d as o3d


def angle_deg(r):
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))))


def main():
    case_dir = sys.argv[1]
    with open(f"{case_dir}/case.json") as f:
        case = json.load(f)
    target = o3d.io.read_point_cloud(f"{case_dir}/target.ply")
    source = o3d.io.read_point_cloud(f"{case_dir}/source.ply")
    start = np.array(case["start"])
    truth = np.array(case["truth"])
    reg = o3d.pipelines.registration
    started = time.perf_counter()
    tgt = target.voxel_down_sample(case["target_voxel_m"])
    tgt.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(radius=case["normal_radius_m"], max_nn=30)
    )
    current = start
    result = None
    for voxel, distance in case["levels"]:
        src = source.voxel_down_sample(voxel)
        result = reg.registration_icp(
            src,
            tgt,
            distance,
            current,
            reg.TransformationEstimationPointToPlane(reg.HuberLoss(k=case["huber_m"])),
            reg.ICPConvergenceCriteria(
                relative_fitness=1e-6,
                relative_rmse=1e-6,
                max_iteration=case["iterations_per_level"],
            ),
        )
        current = result.transformation
    seconds = time.perf_counter() - started
    diff = np.linalg.inv(truth) @ current
    print(
        json.dumps(
            {
                "tool": f"open3d {o3d.__version__}",
                "seconds": seconds,
                "rotation_deg": angle_deg(diff[:3, :3]),
                "translation_cm": float(np.linalg.norm(current[:3, 3] - truth[:3, 3]) * 100.0),
                "fitness": result.fitness,
                "inlier_rmse_cm": result.inlier_rmse * 100.0,
                "source_points": len(source.points),
                "target_points": len(target.points),
                "target_with_normals": len(tgt.points),
            }
        )
    )


if __name__ == "__main__":
    main()
