#!/usr/bin/env python3
"""Wrong loop closures in 3-D on Sphere2500: the batch robust polish, or
the incremental engine.

    cargo build --release --bin slamd
    python3 benches/outliers3.py [--count 1000] [--seeds 1 2] [--kinds random local ...]
    python3 benches/outliers3.py --online [--kinds random]

Each row injects `--count` outliers of one kind with benches/add_outliers3.py
(Vertigo's semantics in SE(3)), runs `slamd solve FILE --robust --json`
(with --online: `slamd replay FILE --embedded --json`, the filter the
engine runs by default), and scores the switched-off loop closures against the side file
(precision, recall) and the map against Sphere2500's noise-free edges (ATE
after rigid alignment). The first row is the clean file.
"""
import argparse, json, os, subprocess, sys, tempfile
from common import BIN, DATA, HERE

KINDS = ("random", "local", "random-grouped", "local-grouped")


def solve(binary, path, truth, online):
    command = ["replay", path, "--embedded"] if online else ["solve", path, "--robust"]
    out = subprocess.run([binary] + command + ["--json", "--ground-truth", truth],
                         check=True, capture_output=True, text=True).stdout
    r = json.loads(out)
    if online:
        r["seconds"] = r["total_s"]
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--file", default="3d/sphere2500.g2o")
    ap.add_argument("--ground-truth", default="3d/groundtruth/sphere2500_groundtruth_isam.txt")
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS))
    ap.add_argument("--online", action="store_true", help="replay through the incremental engine")
    a = ap.parse_args()
    src, truth = os.path.join(DATA, a.file), os.path.join(DATA, a.ground_truth)
    print(f"| {os.path.basename(a.file)} + outliers | seed | loop closures off | precision | recall | ATE (m) | χ² | s |")
    print("|---|---|---|---|---|---|---|---|")
    clean = solve(a.slamd, src, truth, a.online)
    print(f"| clean | – | {len(clean['rejected_edges'])} | – | – | {clean['ate']:.4f} | {clean['chi2']:.2f} | {clean['seconds']:.2f} |")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in a.kinds:
            for seed in a.seeds:
                path = os.path.join(tmp, f"{kind}-{seed}.g2o")
                subprocess.run([sys.executable, os.path.join(HERE, "add_outliers3.py"), "-i", src, "-o", path,
                                "--kind", kind, "--count", str(a.count), "--seed", str(seed)],
                               check=True, capture_output=True)
                side = json.load(open(path + ".outliers.json"))
                wrong = {o["edge_index"] for o in side["outliers"]}
                r = solve(a.slamd, path, truth, a.online)
                off = set(r["rejected_edges"])
                hit = len(wrong & off)
                precision = hit / len(off) if off else 1.0
                print(f"| {kind} {a.count} | {seed} | {len(off)} | {precision:.4f} | {hit / len(wrong):.4f} "
                      f"| {r['ate']:.4f} | {r['chi2']:.0f} | {r['seconds']:.2f} |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
