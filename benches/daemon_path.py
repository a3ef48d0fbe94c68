#!/usr/bin/env python3
"""What the daemon path costs over the engine it wraps.

    python3 benches/daemon_path.py [--runs 2] [FILE ...]

For each file (default Manhattan and City10000), alternates
`slamd replay FILE --embedded --json` and `slamd replay FILE --json`
through a fresh `slamd run` (default configuration, unpinned, in memory),
and prints total, p50, p99 and max per keyframe for each, with the ratio of
the mean totals. The binary is target/release/slamd (build it first) or
$SLAMD_BIN.
"""
import argparse, json, os, signal, statistics, subprocess, time
from common import BIN, DATA

FILES = ["manhattanolson3500_g2oversion.g2o", "city10000.g2o"]


def replay(path, daemon_ns=None):
    args = [BIN, "replay", path, "--json"] + (["--namespace", daemon_ns] if daemon_ns else ["--embedded"])
    out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def through_daemon(path, tag):
    ns = f"slamd-dp-{os.getpid()}-{tag}"
    d = subprocess.Popen([BIN, "run", "--namespace", ns], env=dict(os.environ, SLAMD_LOG="warn"),
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    subprocess.run([BIN, "status", "--namespace", ns, "--wait", "10"], capture_output=True)
    try:
        return replay(path, ns)
    finally:
        d.send_signal(signal.SIGTERM)
        d.wait()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="*", default=FILES)
    ap.add_argument("--runs", type=int, default=2)
    a = ap.parse_intermixed_args()
    print(f"`python3 benches/daemon_path.py --runs {a.runs}`")
    print()
    print("| file | path | total s per run | p50 µs | p99 ms | max ms | χ² | daemon / embedded (mean total) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in a.files:
        path = name if os.path.exists(name) else os.path.join(DATA, name)
        runs = {"embedded": [], "daemon": []}
        for i in range(a.runs):
            runs["embedded"].append(replay(path))
            runs["daemon"].append(through_daemon(path, i))
        mean = {k: statistics.mean(r["total_s"] for r in v) for k, v in runs.items()}
        for k, v in runs.items():
            ratio = f"{mean['daemon'] / mean['embedded']:.2f}" if k == "daemon" else ""
            col = lambda key, scale, fmt: "/".join(format(r[key] * scale, fmt) for r in v)
            totals = " ".join(format(r["total_s"], ".2f") for r in v)
            print(f"| {name} | {k} | {totals} | {col('p50_us', 1, '.0f')} | {col('p99_us', 1e-3, '.2f')} "
                  f"| {col('max_us', 1e-3, '.1f')} | {v[-1]['chi2']:.3f} | {ratio} |")

if __name__ == "__main__":
    main()
