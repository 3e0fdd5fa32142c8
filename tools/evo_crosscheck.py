#!/usr/bin/env python3
"""Print evo's APE (translation part, SE(3) Umeyama alignment) for two TUM files.

Cross-check for `pssba_eval::ape::ape_translation`: it runs the same pipeline
as `evo_ape tum GT EST -a` through evo's Python API (nearest-time association
with `--t_max_diff`, SE(3) alignment of the estimate onto the reference,
translation-part APE) and prints the statistics with full float precision.

Usage:
    pip install evo                      # once; tested with evo 1.38.1
    python3 tools/evo_crosscheck.py GT.txt EST.txt [--max-diff 0.01] [--json] [--cli]

    --max-diff S   max. timestamp difference for association (evo's --t_max_diff),
                   default 0.01 s
    --json         print one JSON object instead of "key value" lines
    --cli          additionally run the `evo_ape tum GT EST -a` command line tool
                   and show its (rounded) output for a visual comparison

Output keys: rmse_m, mean_m, median_m, max_m, min_m, std_m, matched, evo_version.
"""

import argparse
import json
import subprocess
import sys


def evo_ape(gt_path, est_path, max_diff=0.01):
    """Return evo's translation APE statistics (aligned, SE(3)) as a dict."""
    from importlib.metadata import version

    from evo import main_ape
    from evo.core import metrics, sync
    from evo.tools import file_interface

    traj_ref = file_interface.read_tum_trajectory_file(gt_path)
    traj_est = file_interface.read_tum_trajectory_file(est_path)
    traj_ref, traj_est = sync.associate_trajectories(traj_ref, traj_est, max_diff=max_diff)
    result = main_ape.ape(
        traj_ref,
        traj_est,
        metrics.PoseRelation.translation_part,
        align=True,
        correct_scale=False,
    )
    stats = result.stats
    return {
        "rmse_m": float(stats["rmse"]),
        "mean_m": float(stats["mean"]),
        "median_m": float(stats["median"]),
        "max_m": float(stats["max"]),
        "min_m": float(stats["min"]),
        "std_m": float(stats["std"]),
        "matched": int(traj_est.num_poses),
        "evo_version": version("evo"),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("gt", help="reference trajectory (TUM format)")
    parser.add_argument("est", help="estimated trajectory (TUM format)")
    parser.add_argument("--max-diff", type=float, default=0.01)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--cli", action="store_true")
    args = parser.parse_args(argv)

    res = evo_ape(args.gt, args.est, args.max_diff)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        for key, value in res.items():
            print(f"{key} {value!r}" if isinstance(value, float) else f"{key} {value}")
    if args.cli:
        cmd = ["evo_ape", "tum", args.gt, args.est, "-a", "--t_max_diff", repr(args.max_diff)]
        print("$ " + " ".join(cmd), flush=True)
        return subprocess.call(cmd)
    return 0


if __name__ == "__main__":
    sys.exit(main())
