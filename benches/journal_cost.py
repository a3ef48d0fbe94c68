#!/usr/bin/env python3
"""What the state directory costs the daemon path, and how fast a daemon
comes back.

    python3 benches/journal_cost.py [--runs 3] [--sync always] [FILE ...]

For each file (default Manhattan and City10000), alternates runs of
`slamd replay FILE --json` through a fresh `slamd run` without a state
directory and through one with `--state DIR` (journal fsynced as --sync
says), so drift of a shared machine falls on both. Then, from the map the
last run with a state directory left, restarts the daemon --runs times
and times `slamd status --wait` until the restored map is published.
Prints one table per measurement. The binary is target/release/slamd
(build it first) or $SLAMD_BIN.
"""
import argparse, json, os, shutil, signal, statistics, subprocess, tempfile, time
from common import BIN, DATA

FILES = ["manhattanolson3500_g2oversion.g2o", "city10000.g2o"]


def start(ns, state, sync):
    args = [BIN, "run", "--namespace", ns]
    env = dict(os.environ, SLAMD_LOG="warn", SLAMD_STATE__SYNC=sync)
    if state:
        args += ["--state", state]
    d = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return d


def status(ns, wait):
    out = subprocess.run([BIN, "status", "--namespace", ns, "--json", "--wait", str(wait)],
                         capture_output=True, text=True)
    return json.loads(out.stdout) if out.returncode == 0 else None


def stop(d):
    d.send_signal(signal.SIGTERM)
    d.wait()


def replay(path, state, sync, tag):
    ns = f"slamd-jc-{os.getpid()}-{tag}"
    d = start(ns, state, sync)
    status(ns, 10)
    out = subprocess.run([BIN, "replay", path, "--namespace", ns, "--json"],
                         check=True, capture_output=True, text=True).stdout
    stop(d)
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("files", nargs="*", default=FILES)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--sync", default="always")
    a = ap.parse_intermixed_args()
    root = tempfile.mkdtemp(prefix="slamd-jc-")
    print(f"`python3 benches/journal_cost.py --runs {a.runs} --sync {a.sync}`")
    print()
    print("| file | in memory: total s per run | with --state: total s per run | mean ratio | p99 ms in memory / with --state |")
    print("|---|---|---|---|---|")
    restarts = []
    for name in a.files:
        path = name if os.path.exists(name) else os.path.join(DATA, name)
        runs = {"memory": [], "state": []}
        for i in range(a.runs):
            runs["memory"].append(replay(path, None, a.sync, f"m{i}"))
            state = os.path.join(root, f"{os.path.basename(name)}-{i}")
            runs["state"].append(replay(path, state, a.sync, f"s{i}"))
        m = [r["total_s"] for r in runs["memory"]]
        s = [r["total_s"] for r in runs["state"]]
        p99 = lambda rs: "/".join(f"{r['p99_us'] / 1e3:.2f}" for r in rs)
        print(f"| {name} | {' '.join(f'{x:.2f}' for x in m)} | {' '.join(f'{x:.2f}' for x in s)} "
              f"| {statistics.mean(s) / statistics.mean(m):.3f} | {p99(runs['memory'])} / {p99(runs['state'])} |")
        restarts.append((name, state, runs["state"][-1]["keyframes"]))
    print()
    print("| map | keyframes | restart to first snapshot, s per run |")
    print("|---|---|---|")
    for name, state, keyframes in restarts:
        times = []
        for i in range(a.runs):
            ns = f"slamd-jc-{os.getpid()}-r{i}"
            t0 = time.time()
            d = start(ns, state, a.sync)
            while True:
                st = status(ns, 10)
                if st and st["keyframes"] == keyframes:
                    break
            times.append(time.time() - t0)
            stop(d)
        print(f"| {name} | {keyframes} | {' '.join(f'{t:.2f}' for t in times)} |")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
