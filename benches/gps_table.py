#!/usr/bin/env python3
"""GPS: accuracy with and without fixes, in one run.

    cargo build --release --bin slamd
    python3 benches/gps_table.py [--every 20] [--sigma 1.0] [--seed 3]

Fixes come from ../shared/tools/synth_gps.py on each dataset's ground
truth (every --every-th keyframe, Gaussian noise of --sigma m, the tool's
default origin and map heading). Each dataset is solved (two-stage +
polish) with all its edges and with odometry alone, each without and with
GPS; the table reports ATE against ground truth, and for GPS runs the RMSE
of the georeferenced positions against the fixes' true ENU positions.
"""
import argparse, json, os, subprocess, sys, tempfile
from common import BIN, DATA, HERE

TOOL = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "tools", "synth_gps.py"))
ORIGIN = "45.5138,9.2110"  # synth_gps.py's default
CASES = [
    ("manhattanolson3500_g2oversion.g2o", "groundtruth/manhattanolson3500_groundtruth_isam.txt"),
    ("city10000.g2o", "groundtruth/city10000_groundtruth_isam.txt"),
]


def solve(binary, args):
    out = subprocess.run([binary, "solve"] + args + ["--polish", "--json"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--every", type=int, default=20)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    print(f"GPS on every {args.every}th keyframe, σ = {args.sigma} m (slamd solve --polish)")
    print("| dataset | edges | ATE without GPS (m) | ATE with GPS (m) | ENU RMSE with GPS (m) |")
    print("|---|---|---|---|---|")
    for name, gt in CASES:
        fixes = os.path.join(tempfile.gettempdir(), f"slamd-gps-{os.getpid()}-{name}.csv")
        subprocess.run([sys.executable, TOOL, os.path.join(DATA, gt), "--every", str(args.every),
                        "--sigma", str(args.sigma), "--seed", str(args.seed), "--out", fixes], check=True, capture_output=True)
        for label, extra in [("all", []), ("odometry only", ["--odometry-only"])]:
            base = [os.path.join(DATA, name), "--ground-truth", os.path.join(DATA, gt)] + extra
            without = solve(args.slamd, base)
            with_gps = solve(args.slamd, base + ["--gps", fixes, "--gps-origin", ORIGIN])
            print(f"| {name} | {label} | {without['ate']:.4f} | {with_gps['ate']:.4f} | {with_gps['enu_rmse']:.4f} |")
        os.unlink(fixes)


if __name__ == "__main__":
    sys.exit(main())
