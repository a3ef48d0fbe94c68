#!/usr/bin/env python3
"""Eight frontends against one daemon for ten minutes, some killed.

    python3 benches/soak.py [--minutes 10] [--frontends 8] [--rate 10]
                            [--publish-minutes 5] [--kills 8] [--seed 1]

Starts `slamd run --state DIR` and --frontends `slamd-soak-frontend`
processes (benches/soak_frontend.rs), each streaming its own seeded
synthetic world at --rate keyframes a second for the first
--publish-minutes, then staying connected, polling, to the end. --kills
times, at random moments (--seed), one frontend is SIGKILLed and a new one
starts in its place with a fresh world (the next restart number) for what is
left of the publishing window (two keyframes once it is over). Every 10 s
it samples the daemon's RSS and `slamd status --json`.

A growing map grows the daemon, so "flat" is asked of the part where no
frontend publishes: the RSS growth over the last five minutes, after the
publishing window, must stay within 5%. At the end the daemon gets
SIGTERM and its checkpointed map is read: every keyframe a frontend saw
acknowledged (its last `acked N` before it died, or `done N`) must be in
it, and no message may have been rejected.

Binaries: target/release/slamd and target/release/slamd-soak-frontend
(`cargo build --release --workspace`), or $SLAMD_BIN and the frontend
beside it.
"""
import argparse, json, os, random, signal, subprocess, sys, tempfile, threading, time

HERE = os.path.dirname(os.path.abspath(__file__))
RELEASE = os.path.join(HERE, "..", "target", "release")
BIN = os.environ.get("SLAMD_BIN") or os.path.join(RELEASE, "slamd")
FRONTEND = os.path.join(os.path.dirname(BIN), "slamd-soak-frontend")


class Frontend:
    """One frontend process: its world, restart number and last report."""

    def __init__(self, ns, world, restart, keyframes, rate, until):
        self.world, self.restart, self.keyframes = world, restart, keyframes
        self.acked, self.done = 0, False
        self.proc = subprocess.Popen([FRONTEND, ns, str(world), str(restart), str(keyframes),
                                      str(rate), str(until)],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            word, _, n = line.strip().partition(" ")
            if word in ("acked", "done"):
                self.acked = max(self.acked, int(n))
                self.done |= word == "done"

    def ids(self):
        """The ids of the keyframes the daemon acknowledged to it."""
        base = (1000 * self.world + self.restart) << 32
        return range(base, base + self.acked)


def rss_mib(pid):
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def status(ns):
    out = subprocess.run([BIN, "status", "--namespace", ns, "--json", "--wait", "2"],
                         capture_output=True, text=True)
    try:
        return json.loads(out.stdout)
    except ValueError:
        return {}


def map_ids(path):
    """Keyframe ids and edge count of a map file, through `slamd export`."""
    g2o = path + ".g2o"
    subprocess.run([BIN, "export", path, "-o", g2o], check=True, capture_output=True)
    ids, edges = set(), 0
    for line in open(g2o):
        tag = line.split(maxsplit=2)
        if tag and tag[0].startswith("VERTEX"):
            ids.add(int(tag[1]))
        elif tag and tag[0].startswith("EDGE"):
            edges += 1
    return ids, edges


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10)
    ap.add_argument("--frontends", type=int, default=8)
    ap.add_argument("--rate", type=float, default=10)
    ap.add_argument("--publish-minutes", type=float, default=5)
    ap.add_argument("--kills", type=int, default=8)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    total, publish = a.minutes * 60, a.publish_minutes * 60
    state = tempfile.mkdtemp(prefix="slamd-soak-")
    ns = f"slamd-soak-{os.getpid()}"
    log = open(os.path.join(state, "daemon.log"), "w")
    daemon = subprocess.Popen([BIN, "run", "--namespace", ns, "--state", os.path.join(state, "dir")],
                              stdout=log, stderr=log)
    time.sleep(1.0)
    t0 = time.time()

    def start(world, restart):
        left = publish - (time.time() - t0)
        keyframes = max(2, int(a.rate * left))
        return Frontend(ns, world, restart, keyframes, a.rate, max(0.0, total - (time.time() - t0)))

    processes = [start(0, 0)]
    time.sleep(0.5)
    processes += [start(w, 0) for w in range(1, a.frontends)]
    current = list(range(a.frontends))  # index into processes, per world
    kills = sorted(rng.uniform(10, total - 30) for _ in range(a.kills))
    samples, next_sample = [], 0.0
    while time.time() - t0 < total:
        now = time.time() - t0
        if now >= next_sample:
            s = status(ns)
            samples.append((now, rss_mib(daemon.pid), s.get("keyframes"), s.get("edges"),
                            s.get("rejected"), s.get("held")))
            next_sample += 10
        if kills and now >= kills[0]:
            kills.pop(0)
            w = rng.randrange(a.frontends)
            old = processes[current[w]]
            old.proc.send_signal(signal.SIGKILL)
            old.proc.wait()
            processes.append(start(w, old.restart + 1))
            current[w] = len(processes) - 1
        time.sleep(0.2)
    for s in processes:
        if s.proc.poll() is None:
            try:
                s.proc.wait(timeout=150)
            except subprocess.TimeoutExpired:
                s.proc.kill()
                s.proc.wait()
    final = status(ns)
    crashed = daemon.poll() is not None
    if crashed:
        # what it acknowledged is in its journal: a restart folds it in
        daemon = subprocess.Popen([BIN, "run", "--namespace", ns, "--state", os.path.join(state, "dir")],
                                  stdout=log, stderr=log)
        time.sleep(5)
    daemon.send_signal(signal.SIGTERM)
    daemon.wait()
    log.close()
    ids, edges = map_ids(os.path.join(state, "dir", "map"))
    acked = sum(s.acked for s in processes)
    lost = sum(1 for s in processes for i in s.ids() if i not in ids)
    failed = [s for s in processes if s.proc.returncode not in (0, -signal.SIGKILL)]
    print(f"state directory and daemon log: {state}")
    print(f"`python3 benches/soak.py --minutes {a.minutes:g} --frontends {a.frontends} --rate {a.rate:g} "
          f"--publish-minutes {a.publish_minutes:g} --kills {a.kills} --seed {a.seed}`")
    print()
    print("| t (s) | RSS (MiB) | keyframes | edges | rejected | held |")
    print("|---|---|---|---|---|---|")
    for t, rss, k, e, r, h in samples:
        print(f"| {t:.0f} | {rss:.1f} | {k} | {e} | {r} | {h} |")
    last = [r for t, r, *_ in samples if t >= total - 300]
    growth = (last[-1] / last[0] - 1) * 100 if len(last) > 1 else float("nan")
    print()
    print("| daemon | frontend processes | killed | failed | keyframes acknowledged | in the final map "
          "| acknowledged lost | edges in the map | rejected | RSS growth, last 5 min |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    print(f"| {'crashed' if crashed else 'ran through'} | {len(processes)} | {a.kills} | {len(failed)} | {acked} "
          f"| {len(ids)} | {lost} | {edges} | {final.get('rejected')} | {growth:+.1f}% |")
    for s in failed:
        print(f"frontend {s.world}/{s.restart} exited {s.proc.returncode}: {s.proc.stderr.read().strip()}")
    ok = not crashed and lost == 0 and not failed and final.get("rejected") == 0 and growth <= 5
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
