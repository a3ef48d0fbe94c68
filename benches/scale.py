#!/usr/bin/env python3
"""What a keyframe costs as the map grows: synthetic worlds of growing size,
streamed one snapshot per keyframe.

    cargo build --release --bin slamd
    python3 benches/scale.py [--poses 10000 40000 100000] [--daemon]

For each size, `slamd synth --poses N` writes the world, `slamd solve
--polish` gives its batch optimum, and `slamd replay FILE --embedded --json`
streams it (with --daemon: into `slamd run --state DIR` on a namespace of
its own instead). Each replay runs under `/usr/bin/time -v` for its peak
RSS (with --daemon, the daemon's). Prints one table: total time and its
ratio to linear growth from the first size, p50 / p99 / max wait per
keyframe, final χ² against the optimum (`slamd solve --polish`) and against
the batch robust optimum (`slamd solve --robust`: the filter's kernel
polished over the whole file at once), peak RSS and RSS per keyframe;
with --daemon also the pose bytes an average snapshot carried and how many
of the snapshots went out whole (the daemon's closing log line).
The binary is target/release/slamd or $SLAMD_BIN.
"""
import argparse, json, os, re, signal, subprocess, sys, tempfile, time

from common import BIN


def peak_rss(time_report):
    """Peak RSS in MiB from what `/usr/bin/time -v` wrote."""
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", time_report)
    return int(rss.group(1)) / 1024 if rss else float("nan")


def timed(argv):
    """(stdout, peak RSS in MiB) of argv run under /usr/bin/time -v."""
    p = subprocess.run(["/usr/bin/time", "-v", *argv], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed: {p.stderr.strip().splitlines()[-1:]}")
    return p.stdout, peak_rss(p.stderr)


def last_json(text):
    return json.loads(text.strip().splitlines()[-1])


def through_daemon(world, tmp, n):
    """The replay into a daemon with a state directory; the daemon's peak RSS."""
    ns = f"slamd-scale-{os.getpid()}-{n}"
    state = os.path.join(tmp, f"state-{n}")
    # a session of its own: /usr/bin/time ignores SIGINT, so the signal goes
    # to the group, the daemon in it
    daemon = subprocess.Popen(["/usr/bin/time", "-v", BIN, "run", "--namespace", ns, "--state", state],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              env={**os.environ, "SLAMD_LOG": "error,slamd::ipc::engine_loop=info"},
                              start_new_session=True)
    deadline = time.monotonic() + 30
    while subprocess.run([BIN, "status", "--namespace", ns], capture_output=True).returncode != 0:
        if time.monotonic() > deadline:
            daemon.kill()
            sys.exit("the daemon did not come up")
        time.sleep(0.1)
    out = subprocess.run([BIN, "replay", world, "--namespace", ns, "--json", "--timeout", "60"],
                         capture_output=True, text=True)
    os.killpg(daemon.pid, signal.SIGINT)
    _, err = daemon.communicate(timeout=600)
    if out.returncode != 0:
        sys.exit(f"replay of {world} failed: {out.stderr.strip()}")
    r = last_json(out.stdout)
    published = re.search(r"snapshots=(\d+) whole=(\d+) poses=\d+ bytes_per_snapshot=(\d+)",
                          re.sub(r"\x1b\[[0-9;]*m", "", err))
    if published:
        r["snapshots"], r["whole"], r["bytes_per_snapshot"] = map(int, published.groups())
    return r, peak_rss(err)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, nargs="+", default=[10000, 40000])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--daemon", action="store_true", help="stream into `slamd run --state` instead of --embedded")
    args = ap.parse_args()
    rows, tmp = [], tempfile.mkdtemp(prefix="slamd-scale-")
    for n in args.poses:
        world = os.path.join(tmp, f"world-{n}.g2o")
        subprocess.run([BIN, "synth", "--poses", str(n), "--seed", str(args.seed), "--out", world,
                        "--truth", os.path.join(tmp, f"truth-{n}.txt")], check=True, capture_output=True)
        best = last_json(subprocess.run([BIN, "solve", world, "--polish", "--json"], check=True,
                                        capture_output=True, text=True).stdout)["chi2"]
        robust = last_json(subprocess.run([BIN, "solve", world, "--robust", "--json"], check=True,
                                          capture_output=True, text=True).stdout)["chi2"]
        print(f"{n} keyframes: replay …", file=sys.stderr, flush=True)
        if args.daemon:
            r, rss = through_daemon(world, tmp, n)
        else:
            out, rss = timed([BIN, "replay", world, "--embedded", "--json"])
            r = last_json(out)
        rows.append((n, r, best, robust, rss))
    n0, r0 = rows[0][0], rows[0][1]
    extra = " bytes per snapshot | whole snapshots |" if args.daemon else ""
    print(f"| keyframes | total s | × linear from {n0:,} | p50 µs | p99 ms | max ms | χ² / optimum | "
          f"χ² / robust optimum | peak RSS MiB | KiB per keyframe |{extra}")
    print("|---|---|---|---|---|---|---|---|---|---|" + ("---|---|" if args.daemon else ""))
    for n, r, best, robust, rss in rows:
        linear = r["total_s"] / (r0["total_s"] * n / n0)
        row = (f"| {n:,} | {r['total_s']:.1f} | {linear:.2f} | {r['p50_us']:.0f} | {r['p99_us'] / 1e3:.1f} | "
               f"{r['max_us'] / 1e3:.0f} | {r['chi2'] / best:.4f} | {r['chi2'] / robust:.4f} | {rss:.0f} | "
               f"{rss * 1024 / n:.1f} |")
        if args.daemon:
            row += (f" {r.get('bytes_per_snapshot', float('nan')):,} | "
                    f"{r.get('whole', 0):,} of {r.get('snapshots', 0):,} |")
        print(row)
    how = "`slamd replay` into `slamd run --state`" if args.daemon else "`slamd replay --embedded`"
    print(f"\n- {how}, synth seed {args.seed}; one run each")


if __name__ == "__main__":
    main()
