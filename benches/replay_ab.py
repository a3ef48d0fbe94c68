#!/usr/bin/env python3
"""Two slamd binaries replaying the same files, alternated, in one run.

    python3 benches/replay_ab.py BEFORE AFTER [--runs 3] [--check-prefixes N] [FILE ...]

Each run is `BIN replay FILE --embedded --json`; the runs of the two
binaries alternate (A B A B ...), so drift of a shared machine falls on
both. Prints, per file and binary, the final χ² of every run, the total
times, their mean, and the mean ratio AFTER / BEFORE. Files default to
Manhattan and City10000 from SLAMD_DATASETS (default ../shared/datasets).
With `--check-prefixes N`, each run also checks N sampled snapshots
against their prefix's optimum and the worst ratio is printed.
"""
import argparse, json, os, subprocess, sys
from common import DATA

FILES = ["manhattanolson3500_g2oversion.g2o", "city10000.g2o"]


def replay(binary, path, prefixes):
    extra = ["--check-prefixes", str(prefixes)] if prefixes else []
    out = subprocess.run([binary, "replay", path, "--embedded", "--json"] + extra,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("files", nargs="*", default=FILES)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--check-prefixes", type=int, default=0)
    a = ap.parse_intermixed_args()
    print("| file | binary | final χ² per run | total s per run | mean s | p99 ms per run "
          "| max ms per run | worst prefix per run |")
    print("|---|---|---|---|---|---|---|---|")
    for name in a.files:
        path = name if os.path.exists(name) else os.path.join(DATA, name)
        runs = {"before": [], "after": []}
        for _ in range(a.runs):
            for label, binary in (("before", a.before), ("after", a.after)):
                runs[label].append(replay(binary, path, a.check_prefixes))
        means = {}
        for label, rs in runs.items():
            means[label] = sum(r["total_s"] for r in rs) / len(rs)
            chi2 = " / ".join("%.3f" % r["chi2"] for r in rs)
            total = " / ".join("%.2f" % r["total_s"] for r in rs)
            p99 = " / ".join("%.2f" % (r["p99_us"] / 1000) for r in rs)
            worst_max = " / ".join("%.1f" % (r["max_us"] / 1000) for r in rs)
            worst = " / ".join("%.3f" % r["worst_prefix_ratio"] if r.get("worst_prefix_ratio") else "–"
                               for r in rs)
            print(f"| {os.path.basename(path)} | {label} | {chi2} | {total} | {means[label]:.2f} | {p99} "
                  f"| {worst_max} | {worst} |")
        ratio = means["after"] / means["before"]
        print(f"| {os.path.basename(path)} | after / before | | | {ratio:.3f} | | | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
