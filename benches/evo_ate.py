#!/usr/bin/env python3
"""evo's ATE of slamd's TUM trajectories against the ATE slamd prints.

    cargo build --release --bin slamd
    pip install evo
    python3 benches/evo_ate.py

Per file, one run: the ground truth (a noise-free iSAM graph) is written as
TUM by `slamd solve GT --formulation odometry --out gt.tum` (its poses
composed along the odometry; `--ground-truth` composes the same noise-free
edges along a breadth-first spanning tree, so the two truths differ only
by the file's rounding), the
estimate by `slamd solve FILE --polish --ground-truth GT --out est.tum
--json`, and `evo_ape tum gt.tum est.tum -a` (SE(3) Umeyama alignment)
scores it. The table gives both RMSEs and their difference.
"""
import json, os, re, subprocess, sys, tempfile
from common import BIN, DATA

CASES = [
    ("manhattanolson3500.g2o", "groundtruth/manhattanolson3500_groundtruth_isam.txt"),
    ("city10000.g2o", "groundtruth/city10000_groundtruth_isam.txt"),
]


def evo_ape():
    exe = os.path.join(os.path.dirname(sys.executable), "evo_ape")
    return exe if os.path.exists(exe) else "evo_ape"


def main():
    print("| file | slamd ATE m | evo_ape RMSE m | difference m |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        gt, est = os.path.join(tmp, "gt.tum"), os.path.join(tmp, "est.tum")
        for name, truth in CASES:
            truth = os.path.join(DATA, truth)
            subprocess.run([BIN, "solve", truth, "--formulation", "odometry", "--out", gt],
                           check=True, capture_output=True)
            run = subprocess.run([BIN, "solve", os.path.join(DATA, name), "--polish", "--ground-truth", truth,
                                  "--out", est, "--json"], check=True, capture_output=True, text=True)
            ours = json.loads(run.stdout)["ate"]
            ours = ours["rmse"] if isinstance(ours, dict) else ours
            evo = subprocess.run([evo_ape(), "tum", gt, est, "-a"], check=True, capture_output=True, text=True)
            theirs = float(re.search(r"rmse\s+([0-9.eE+-]+)", evo.stdout).group(1))
            print(f"| {name} | {ours:.7f} | {theirs:.7f} | {abs(ours - theirs):.1e} |", flush=True)


if __name__ == "__main__":
    main()
