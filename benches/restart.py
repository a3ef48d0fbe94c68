#!/usr/bin/env python3
"""How fast a large map comes back from its state directory, and goes on.

    python3 benches/restart.py [--poses 1000000] [--tail 1000] [--runs 3] [--no-filter]

Writes `slamd synth --poses N`'s world and a file of its first N − tail
keyframes (the edges between them), solves that prefix in batch and saves
it as a map (`slamd solve PREFIX --polish --out PREFIX.map`), serves it
once with `slamd run --map PREFIX.map --state DIR` so that the state
directory holds it, then restarts `slamd run --state DIR` --runs times and
times each from the process start to a status that counts the restored
keyframes. The last daemon takes the world's remaining `tail` keyframes
(`slamd replay WORLD --from N−tail`), one snapshot each; the final χ² is
set against the whole world's batch optimum. `--no-filter` serves with the
outlier filter off (`engine.outliers.enabled = false`: no judge, whose
copy of the map doubles memory). Prints one table. The binary
is target/release/slamd (build it first) or $SLAMD_BIN.
"""
import argparse, json, os, shutil, subprocess, tempfile, time
from common import BIN
from journal_cost import status, stop


def timed(args):
    """Runs `args` under /usr/bin/time; returns stdout, seconds, peak RSS MiB."""
    t0 = time.time()
    p = subprocess.run(["/usr/bin/time", "-f", "%M", *args], capture_output=True, text=True, check=True)
    return p.stdout, time.time() - t0, int(p.stderr.strip().splitlines()[-1]) / 1024


def prefix(world, out, keep):
    """The keyframes of `world` with id < keep and the edges between them."""
    with open(world) as f, open(out, "w") as g:
        for line in f:
            t = line.split()
            if t and t[0].startswith("VERTEX") and int(t[1]) >= keep:
                continue
            if t and t[0].startswith("EDGE") and max(int(t[1]), int(t[2])) >= keep:
                continue
            g.write(line)


def serve(ns, args, filtered):
    """Starts `slamd run`; returns it and the seconds until its status
    counts keyframes (the restored map is out)."""
    t0 = time.time()
    env = dict(os.environ, SLAMD_LOG="warn", SLAMD_ENGINE__OUTLIERS__ENABLED=str(filtered).lower())
    d = subprocess.Popen([BIN, "run", "--namespace", ns, *args], env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while True:
        st = status(ns, 5)
        if st and st["keyframes"] > 0:
            return d, time.time() - t0
        if d.poll() is not None:
            raise SystemExit(f"slamd run exited {d.returncode}")
        time.sleep(0.05)


def peak_mib(pid):
    with open(f"/proc/{pid}/status") as f:
        return next(int(l.split()[1]) for l in f if l.startswith("VmHWM")) / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=1_000_000)
    ap.add_argument("--tail", type=int, default=1000)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-filter", action="store_true")
    a = ap.parse_args()
    root = tempfile.mkdtemp(prefix="slamd-restart-")
    world, part, saved = (os.path.join(root, n) for n in ("world.g2o", "prefix.g2o", "prefix.map"))
    state = os.path.join(root, "state")
    keep = a.poses - a.tail
    subprocess.run([BIN, "synth", "--poses", str(a.poses), "--seed", str(a.seed), "--out", world,
                    "--truth", os.path.join(root, "truth.txt")], check=True, capture_output=True)
    prefix(world, part, keep)
    _, solve_s, solve_mib = timed([BIN, "solve", part, "--polish", "--out", saved])
    ns = f"slamd-restart-{os.getpid()}"
    d, first_s = serve(ns, ["--map", saved, "--state", state], not a.no_filter)
    t0 = time.time()
    stop(d)
    checkpoint_s = time.time() - t0
    restarts = []
    for i in range(a.runs):
        d, s = serve(ns, ["--state", state], not a.no_filter)
        restarts.append(s)
        if i + 1 < a.runs:
            stop(d)
    out = subprocess.run([BIN, "replay", world, "--namespace", ns, "--from", str(keep), "--json", "--timeout", "60"],
                         capture_output=True, text=True, check=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    rss = peak_mib(d.pid)
    stop(d)
    optimum, _, _ = timed([BIN, "solve", world, "--polish", "--json"])
    best = json.loads(optimum)["chi2"]
    flag = " --no-filter" if a.no_filter else ""
    print(f"`python3 benches/restart.py --poses {a.poses} --tail {a.tail} --runs {a.runs}{flag}`")
    print()
    print("| keyframes restored | map file MB | batch solve + save, s | first start from `--map`, s | checkpoint on SIGTERM, s "
          "| restart to first snapshot, s per run | then tail keyframes | tail total s | p50 µs | p99 ms | max ms "
          "| χ² / optimum | daemon peak RSS MiB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    print(f"| {keep:,} | {os.path.getsize(os.path.join(state, 'map')) / 1e6:.0f} | {solve_s:.1f} ({solve_mib:.0f} MiB) "
          f"| {first_s:.2f} | {checkpoint_s:.2f} | {' '.join(f'{s:.2f}' for s in restarts)} | {a.tail:,} "
          f"| {r['total_s']:.2f} | {r['p50_us']:.0f} | {r['p99_us'] / 1e3:.1f} | {r['max_us'] / 1e3:.0f} "
          f"| {r['chi2'] / best:.4f} | {rss:.0f} |")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
