#!/usr/bin/env python3
"""A stream through a daemon that is SIGKILLed again and again.

    python3 benches/crash.py [--kills 20] [--rate 800] [--seed 1] [--gap 0.2 0.8] [FILE]

Starts `slamd run --state DIR`, replays FILE (default City10000) through
it at --rate keyframes a second, and SIGKILLs the daemon at random
moments (--gap MIN MAX seconds apart, drawn with --seed), restarting it on the same
state directory after each kill, until --kills kills. Then it waits for
the replay, stops the daemon with SIGTERM and reads the map it left.
Prints one table: kills, restarts seen in the daemon's log, the replay's
final χ² and the uninterrupted optimum (`slamd solve --polish`), and the
keyframes and edges in the file, in the replay and in the final map.
The binary is target/release/slamd (build it first) or $SLAMD_BIN.
"""
import argparse, json, os, random, signal, subprocess, sys, tempfile, time
from common import BIN, DATA


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file", nargs="?", default="city10000.g2o")
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--rate", type=float, default=800.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--gap", type=float, nargs=2, default=[0.2, 0.8])
    a = ap.parse_args()
    path = a.file if os.path.exists(a.file) else os.path.join(DATA, a.file)
    rng = random.Random(a.seed)
    state = tempfile.mkdtemp(prefix="slamd-crash-")
    ns = f"slamd-crash-{os.getpid()}"
    log = open(os.path.join(state, "daemon.log"), "w")
    env = dict(os.environ, SLAMD_LOG=os.environ.get("CRASH_LOG", "info"))

    def start():
        return subprocess.Popen([BIN, "run", "--namespace", ns, "--state", os.path.join(state, "dir")],
                                stdout=log, stderr=log, env=env)

    daemon = start()
    time.sleep(1.0)
    trace = os.path.join(state, "latency.txt")
    t0 = time.time()
    replay = subprocess.Popen([BIN, "replay", path, "--namespace", ns, "--json", "--timeout", "120",
                               "--rate", str(a.rate), "--trace", trace], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    kills = 0
    while kills < a.kills and replay.poll() is None:
        time.sleep(rng.uniform(*a.gap))
        daemon.send_signal(signal.SIGKILL)
        daemon.wait()
        kills += 1
        log.write(f"killed at {time.time() - t0:.3f} s\n")
        log.flush()
        daemon = start()
    out, err = replay.communicate()
    open(os.path.join(state, "replay.err"), "w").write(err)
    if replay.returncode != 0:
        daemon.kill()
        sys.exit(f"replay failed after {kills} kills: {err} (logs in {state})")
    time.sleep(0.5)
    daemon.send_signal(signal.SIGTERM)
    daemon.wait()
    log.close()
    r = json.loads(out.strip().splitlines()[-1])
    print(f"state directory, daemon log and latency trace: {state}")
    restarts = sum("Map restored" in line for line in open(os.path.join(state, "daemon.log")))
    final = json.loads(subprocess.run([BIN, "solve", os.path.join(state, "dir", "map"), "--json"],
                                      check=True, capture_output=True, text=True).stdout)
    best = json.loads(subprocess.run([BIN, "solve", path, "--polish", "--json"],
                                     check=True, capture_output=True, text=True).stdout)
    print(f"`python3 benches/crash.py {os.path.basename(path)} --kills {a.kills} --rate {a.rate:g} "
          f"--seed {a.seed} --gap {a.gap[0]:g} {a.gap[1]:g}`")
    print()
    print("| kills | restarts that restored | replay χ² | optimum χ² | keyframes file / replay / map | edges file / replay / map | replay s | max wait s |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {kills} | {restarts} | {r['chi2']:.3f} | {best['chi2']:.3f} "
          f"| {best['nodes']} / {r['keyframes']} / {final['nodes']} "
          f"| {best['edges']} / {r['edges']} / {final['edges']} "
          f"| {r['total_s']:.1f} | {r['max_us'] / 1e6:.2f} |")


if __name__ == "__main__":
    main()
