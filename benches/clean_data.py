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
$SLAMD_DATASETS/3d/*.g2o $SLAMD_DATASETS/3d/*.graph`). `--gnc SECONDS`
adds GTSAM's GNC on each file in the same run (benches/peer_gnc.py): the
loop closures it holds off and its RMSE to the same polish. The binary is
target/release/slamd (build it first) or $SLAMD_BIN.
"""
import argparse, glob, os, subprocess, sys, tempfile
from common import BIN, DATA, slamd


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="*")
    ap.add_argument("--gnc", type=float, default=0, help="GTSAM's GNC beside, with this timeout in seconds")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="slamd-clean-")
    files = a.files or sorted(glob.glob(os.path.join(DATA, "*.g2o")) + glob.glob(os.path.join(DATA, "*.graph")))
    demo = os.path.join(tmp, "demo-world.g2o")
    subprocess.run([BIN, "synth", "--poses", "3000", "--seed", "7", "--out", demo,
                    "--truth", os.path.join(tmp, "demo-truth.txt")], check=True, capture_output=True)
    if not a.files:
        files.append(demo)
    print("`python3 benches/clean_data.py" + (f" --gnc {a.gnc:g}`" if a.gnc else "`"))
    print()
    gnc_head = " GNC off | GNC RMSE (m) | GNC (s) |" if a.gnc else ""
    print("| file | loop closures | switched off | share | RMSE to the polish (m) | χ² polish | χ² replay | replay (s) | p99 (ms) | max (ms) |" + gnc_head)
    print("|---|---|---|---|---|---|---|---|---|---|" + "---|" * (3 if a.gnc else 0))
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
            print(f"| {name} | refused: {reason[0].replace('|', '/')} |" + " |" * (11 if a.gnc else 8))
            continue
        share = r["switched_off"] / max(1, r["loop_closures"])
        rmse = e["ate"]
        print(f"| {name} | {r['loop_closures']} | {r['switched_off']} | {100 * share:.2f}% "
              f"| {rmse:.4f} | {p['chi2']:.3f} | {r['chi2']:.3f} | {r['total_s']:.2f} "
              f"| {r['p99_us'] / 1e3:.1f} | {r['max_us'] / 1e3:.0f} |" + (gnc_row(path, polished, a.gnc) if a.gnc else ""))
    return 0


def gnc_row(path, polished, timeout):
    """GTSAM's GNC on `path`: its cells, scored against the same polish."""
    from peer_gnc import gnc
    g = gnc(path, timeout)
    if "reason" in g:
        return f" {g['reason'].replace('|', '/')} | | |"
    e = slamd("eval", path, g["poses"], "--ground-truth", polished, "--json")
    return f" {g['off']} | {e['ate']:.4f} | {g['seconds']:.1f} |"


if __name__ == "__main__":
    sys.exit(main())
