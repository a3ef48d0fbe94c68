#!/usr/bin/env python3
"""Whether the outlier filter switches off the same loop closures on every run.

    cargo build --release --bin slamd
    python3 benches/reproducible.py [--runs 5] [--parallel 2] [--seed 1]

Each case (a dataset, with Vertigo-style wrong loop closures from
../shared/tools/add_outliers.py or clean) is replayed `--runs` times with
`slamd replay --embedded`, `--parallel` replays at a time, so that they
share the machine's two cores and the filter's threads run at different
speeds each time. Prints, per case, how many distinct sets of switched-off
loop closures the runs ended with (1: reproducible), the sizes of those
sets, and the runs' total times. The binary is target/release/slamd or
$SLAMD_BIN.
"""
import argparse, json, os, subprocess, sys, tempfile
from concurrent.futures import ThreadPoolExecutor

from common import BIN, DATA

TOOL = os.path.join(DATA, "..", "tools", "add_outliers.py")
CASES = [  # (name, file, kind, count); kind None: the file as it is
    ("manhattan + 4000 random", "manhattanolson3500_g2oversion.g2o", "random", 4000),
    ("intel + 1000 local-grouped", "intel_sesync.g2o", "local-grouped", 1000),
    ("w10000", "w10000.graph", None, 0),
    ("city10000 + 1000 random-grouped", "city10000.g2o", "random-grouped", 1000),
]


def replay(path):
    out = subprocess.run([BIN, "replay", path, "--embedded", "--json"], check=True, capture_output=True, text=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    return frozenset(r["rejected_edges"] or []), r["total_s"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--parallel", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="slamd-reproducible-")
    print(f"`python3 benches/reproducible.py --runs {args.runs} --parallel {args.parallel} --seed {args.seed}`")
    print()
    print("| case | runs | distinct switched-off sets | their sizes | total (s), each run |")
    print("|---|---|---|---|---|")
    for name, file, kind, count in CASES:
        path = os.path.join(DATA, file)
        if kind is not None:
            spoiled = os.path.join(tmp, f"{file}-{kind}-{count}.g2o")
            subprocess.run([sys.executable, TOOL, "-i", path, "-o", spoiled, "--kind", kind,
                            "--count", str(count), "--seed", str(args.seed)], check=True, capture_output=True)
            path = spoiled
        with ThreadPoolExecutor(args.parallel) as pool:
            results = list(pool.map(replay, [path] * args.runs))
        sets = {s for s, _ in results}
        sizes = ", ".join(str(len(s)) for s in sets)
        times = ", ".join(f"{t:.1f}" for _, t in results)
        print(f"| {name} | {args.runs} | {len(sets)} | {sizes} | {times} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
