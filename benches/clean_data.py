#!/usr/bin/env python3
"""What the outlier filter costs on graphs with no wrong loop closure.

    python3 benches/clean_data.py [FILE ...]

For every 2-D graph file in SLAMD_DATASETS (default ../shared/datasets:
all of *.g2o and *.graph) and for `slamd demo`'s world (`slamd synth
--poses 3000 --seed 7`), runs `slamd solve FILE --polish` (every edge
trusted) and `slamd replay FILE --embedded` (the filter on, as shipped),
then scores the replay's map against the polish's with `slamd eval`
(RMSE after the best rigid alignment). Prints one table: loop closures,
how many the filter ended holding switched off, the RMSE, both χ², and
the replay's time, p99 and longest wait for a keyframe's snapshot.
A file slamd refuses is a row with its reason. 3-D files are named
on the command line (`python3 benches/clean_data.py
$SLAMD_DATASETS/3d/*.g2o $SLAMD_DATASETS/3d/*.graph`). The binary is
target/release/slamd (build it first) or $SLAMD_BIN.
"""
import glob, os, subprocess, sys, tempfile
from common import BIN, DATA, slamd


def main():
    tmp = tempfile.mkdtemp(prefix="slamd-clean-")
    files = sys.argv[1:] or sorted(glob.glob(os.path.join(DATA, "*.g2o")) + glob.glob(os.path.join(DATA, "*.graph")))
    demo = os.path.join(tmp, "demo-world.g2o")
    subprocess.run([BIN, "synth", "--poses", "3000", "--seed", "7", "--out", demo,
                    "--truth", os.path.join(tmp, "demo-truth.txt")], check=True, capture_output=True)
    if not sys.argv[1:]:
        files.append(demo)
    print("`python3 benches/clean_data.py`")
    print()
    print("| file | loop closures | switched off | share | RMSE to the polish (m) | χ² polish | χ² replay | replay (s) | p99 (ms) | max (ms) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in files:
        name = os.path.basename(path)
        polished = os.path.join(tmp, name + ".polish.txt")
        replayed = os.path.join(tmp, name + ".replay.txt")
        try:
            p = slamd("solve", path, "--polish", "--out", polished, "--json")
            r = slamd("replay", path, "--embedded", "--out", replayed, "--json")
            e = slamd("eval", path, replayed, "--ground-truth", polished, "--json")
        except subprocess.CalledProcessError as err:
            # a file slamd refuses is a row with slamd's reason, not the end of the table
            reason = (err.stderr or "").strip().splitlines()[-1:] or [f"exit {err.returncode}"]
            print(f"| {name} | refused: {reason[0].replace('|', '/')} |" + " |" * 8)
            continue
        share = r["switched_off"] / max(1, r["loop_closures"])
        rmse = e["ate"]
        print(f"| {name} | {r['loop_closures']} | {r['switched_off']} | {100 * share:.2f}% "
              f"| {rmse:.4f} | {p['chi2']:.3f} | {r['chi2']:.3f} | {r['total_s']:.2f} "
              f"| {r['p99_us'] / 1e3:.1f} | {r['max_us'] / 1e3:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
