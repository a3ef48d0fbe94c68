#!/usr/bin/env python3
"""slamd's online replay against GTSAM's iSAM2, in one run.

    cargo build --release --bin slamd
    pip install gtsam
    python3 benches/peer_isam2.py [FILE ...]         # 2-D table
    python3 benches/peer_isam2.py --3d [FILE ...]    # 3-D table
        [--peer-timeout S] [--isam2-factorization qr] [--no-qr-retry]

2-D (default files: manhattanolson3500, city10000, w10000). Both stream the
same edges, as written, in time order (sorted by max(i, j), then min(i, j))
and produce a whole estimate after
every keyframe: slamd's snapshot, and iSAM2's update() followed by
calculateEstimate(). Latency per keyframe runs from the arrival of its edges
to the estimate; each side also ends with its final answer (slamd: a last
re-solve; iSAM2: its last estimate), scored by `slamd eval` with g2o's chi2.
Peak RSS is read for each side as a child process.

3-D (--3d; default files: sphere2500, parking-garage, torus3d under
DATASETS/3d; a FILE that is not a path is looked up there). slamd runs
`slamd replay FILE --embedded --json` (3-D detected from the file), once with
its outlier filter (the default) and once with `--no-filter`; each is timed
alone, and its worst sampled prefix ratio comes from a separate, untimed run
with `--check-prefixes 5` added (checking slows the replay). The batch optimum
is `slamd solve FILE --polish --json`. iSAM2 (default ISAM2Params:
Gauss-Newton, Cholesky, relinearizeThreshold 0.1, relinearizeSkip 10) gets one
update() per keyframe, in the order slamd streams (newer end, then older end,
ties in file order): that keyframe's edges as BetweenFactorPose3(i, j, Z),
as written; an initial value for the new keyframe composed from the current
estimate of the older end of its odometry edge with k-1, or failing that of
its first edge to an existing keyframe; and, in the first update, the first keyframe at
the identity with a tight PriorFactorPose3. Each update is followed by
calculateEstimate(). The information is built here as in
benches/peer_gtsam.py (its read_3d), not taken from readG2o: g2o's Ω over
(x y z qx qy qz) becomes Ω_gtsam = P D Ω D Pᵀ, D = diag(1, 1, 1, ½, ½, ½)
(the quaternion vector is half the rotation vector), P the permutation to
GTSAM's [rotation; translation]. iSAM2's last estimate is scored by
`slamd eval FILE POSES --json` (POSES: `id x y z qx qy qz qw` lines). Time
excludes reading the file on both sides; iSAM2's includes building the
factors. An iSAM2 run that raises or exceeds --peer-timeout is reported as
failing, with the keyframe it had reached; one whose Cholesky factorization
finds the system indeterminate (parking-garage.g2o at keyframe 585, as in
borglab/gtsam#406) is run again with factorization QR, and the figures of
that run are marked (--no-qr-retry: report the failure only).
"""
import argparse, json, os, subprocess, sys, tempfile, threading, time
from common import BIN, DATA

DEFAULT = ["manhattanolson3500_g2oversion.g2o", "city10000.g2o", "w10000.graph"]
DEFAULT3 = ["sphere2500.g2o", "parking-garage.g2o", "torus3d.g2o"]  # under DATA/3d


def read_graph(path):
    """Edges (i, j, x, y, theta, info6 in g2o order) as written, in time order."""
    toro = path.endswith(".graph")
    edges = []
    for line in open(path):
        t = line.split()
        if not t or t[0] not in ("EDGE_SE2", "EDGE2"):
            continue
        i, j = int(t[1]), int(t[2])
        x, y, th = map(float, t[3:6])
        v = list(map(float, t[6:12]))
        info = [v[0], v[1], v[4], v[2], v[5], v[3]] if toro else v
        edges.append((i, j, x, y, th, info))
    edges.sort(key=lambda e: (max(e[0], e[1]), min(e[0], e[1])))
    return edges


def isam2_replay(path):
    """iSAM2 over a 2-D file, one update and one whole estimate per keyframe;
    (final estimate, stats). Every 1000 keyframes a progress line on stderr
    says how far it got (what a timed-out run reports)."""
    import gtsam
    import numpy as np

    edges = read_graph(path)
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    result = gtsam.Values()
    result.insert(0, gtsam.Pose2())
    latencies, by_key = [], {}
    for e in edges:
        by_key.setdefault(max(e[0], e[1]), []).append(e)
    start = time.perf_counter()
    first = True
    keys = sorted(by_key)
    for n, k in enumerate(keys):
        t0 = time.perf_counter()
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if first:
            graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-6, 1e-6, 1e-8]))))
            values.insert(0, gtsam.Pose2())
            first = False
        for i, j, x, y, th, I in by_key[k]:
            omega = np.array([[I[0], I[1], I[2]], [I[1], I[3], I[4]], [I[2], I[4], I[5]]])
            z = gtsam.Pose2(x, y, th)
            graph.add(gtsam.BetweenFactorPose2(i, j, z, gtsam.noiseModel.Gaussian.Information(omega)))
            # the new end starts from the last estimate of the other, looked
            # up in GTSAM's Values (a Python copy of the whole estimate per
            # keyframe would cost more than iSAM2 itself)
            if not result.exists(j) and not values.exists(j) and result.exists(i):
                values.insert(j, result.atPose2(i).compose(z))
            elif not result.exists(i) and not values.exists(i) and result.exists(j):
                values.insert(i, result.atPose2(j).compose(z.inverse()))
        isam.update(graph, values)
        result = isam.calculateEstimate()
        latencies.append((time.perf_counter() - t0) * 1e6)
        if (n + 1) % 1000 == 0:
            print(f"keyframe {n + 1} of {len(keys)} at {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    total = time.perf_counter() - start
    estimate = {key: result.atPose2(key) for key in result.keys()}
    latencies.sort()
    pct = lambda q: latencies[round((len(latencies) - 1) * q)]
    return estimate, {"p50_us": pct(0.5), "p99_us": pct(0.99), "max_us": latencies[-1], "total_s": total}


class Isam2Failed(RuntimeError):
    pass


def isam2_replay3(path, factorization):
    """iSAM2 over a 3-D file, one update per keyframe; (final Values, stats)."""
    import gtsam
    import numpy as np

    from peer_gtsam import first_paragraph, read_3d

    _, edges = read_3d(path)  # (i, j, Z, Ω in GTSAM's order) as written, file order
    edges.sort(key=lambda e: (max(e[0], e[1]), min(e[0], e[1])))  # stable: ties stay in file order
    by_key = {}
    for e in edges:
        by_key.setdefault(max(e[0], e[1]), []).append(e)
    first = min(e[0] for e in edges)
    prior = gtsam.noiseModel.Diagonal.Variances(np.array([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4]))
    params = gtsam.ISAM2Params()
    params.setFactorization(factorization.upper())
    isam = gtsam.ISAM2(params)
    known, result = {first}, None
    latencies, keys = [], sorted(by_key)
    start = time.perf_counter()
    for n, k in enumerate(keys):
        t0 = time.perf_counter()
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if result is None:
            graph.add(gtsam.PriorFactorPose3(first, gtsam.Pose3(), prior))
            values.insert(first, gtsam.Pose3())
        seed = None
        for i, j, z, omega in by_key[k]:
            # the older end and the motion from it to k
            older, step = (i, z) if j == k else (j, z.inverse())
            if older not in known:
                raise RuntimeError(f"keyframe {k}: edge from {older}, which has no estimate yet")
            graph.add(gtsam.BetweenFactorPose3(i, j, z, gtsam.noiseModel.Gaussian.Information(omega)))
            if seed is None or older == k - 1:
                seed = (older, step)
        i, z = seed
        values.insert(k, (result.atPose3(i) if result is not None else gtsam.Pose3()).compose(z))
        known.add(k)
        try:
            isam.update(graph, values)
            result = isam.calculateEstimate()
        except RuntimeError as e:
            raise Isam2Failed(f"update() for keyframe {k}, {n + 1} of {len(keys)}, raised {first_paragraph(e)}") from e
        latencies.append((time.perf_counter() - t0) * 1e6)
        if n % 100 == 0:
            print(f"keyframe {n + 1} of {len(keys)} at {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    total = time.perf_counter() - start
    latencies.sort()
    pct = lambda q: latencies[round((len(latencies) - 1) * q)]
    return result, {"p50_us": pct(0.5), "p99_us": pct(0.99), "max_us": latencies[-1], "total_s": total}


class ChildFailed(RuntimeError):
    """A child that exited non-zero or was killed at its timeout; `last` is its last line of stderr."""

    def __init__(self, message, last, timed_out):
        super().__init__(message)
        self.last, self.timed_out = last, timed_out


def run_child(argv, timeout=None):
    """Runs argv, returns (stdout, peak RSS in MiB of that very child).

    With `timeout` (seconds; 0: none), keeps the child's stderr and kills the
    child after `timeout`; a failing child raises ChildFailed."""
    err = tempfile.TemporaryFile("w+") if timeout is not None else subprocess.DEVNULL
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=err, text=True)
    timer, fired = None, threading.Event()
    if timeout:
        timer = threading.Timer(timeout, lambda: (fired.set(), p.kill()))
        timer.start()
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if timer:
        timer.cancel()
    if p.returncode != 0:
        last = ""
        if timeout is not None:
            err.seek(0)
            lines = err.read().strip().splitlines()
            last = lines[-1] if lines else ""
        if fired.is_set():
            raise ChildFailed(f"timed out after {timeout:g} s" + (f", {last}" if last else ""), last, True)
        raise ChildFailed(f"{os.path.basename(argv[0])} exited with {p.returncode}" + (f": {last}" if last else ""), last, False)
    return out, usage.ru_maxrss / 1024.0


def isam2_3d(args, path, factorization):
    """One iSAM2 child over a 3-D file: (stats, peak RSS MiB, χ² by slamd eval, None) or (None, None, None, reason)."""
    try:
        out, rss = run_child([sys.executable, __file__, "--isam2-child3", path, "--isam2-factorization", factorization],
                             timeout=args.peer_timeout)
    except ChildFailed as e:
        return None, None, None, str(e) if e.timed_out or not e.last else e.last
    stats = json.loads(out)
    try:
        scored = json.loads(subprocess.run([args.slamd, "eval", path, stats["poses"], "--json"],
                                           check=True, capture_output=True, text=True).stdout)
    except subprocess.CalledProcessError as e:
        return None, None, None, "slamd eval of its poses fails: " + (e.stderr.strip().splitlines() or ["?"])[0]
    finally:
        os.unlink(stats["poses"])
    return stats, rss, scored["chi2"], None


def table_3d(args):
    rows, notes = [], []
    for name in args.files or DEFAULT3:
        path = name if os.path.exists(name) else os.path.join(DATA, "3d", name)
        base = os.path.basename(path)
        print(f"{base}: slamd …", file=sys.stderr, flush=True)
        runs = {}
        for label, flags in (("", []), ("--no-filter", ["--no-filter"])):
            out, rss = run_child([args.slamd, "replay", path, "--embedded", "--json"] + flags)
            timed = json.loads(out)
            out, _ = run_child([args.slamd, "replay", path, "--embedded", "--json", "--check-prefixes", "5"] + flags)
            timed["prefix_run"] = json.loads(out)
            runs[label] = (timed, rss)
        optimum = json.loads(subprocess.run([args.slamd, "solve", path, "--polish", "--json"],
                                            check=True, capture_output=True, text=True).stdout)["chi2"]
        print(f"{base}: iSAM2 ({args.isam2_factorization}) …", file=sys.stderr, flush=True)
        peer, peer_rss, peer_chi2, peer_fail = isam2_3d(args, path, args.isam2_factorization)
        mark = ""
        if peer_fail and args.isam2_factorization == "cholesky" and "ndetermin" in peer_fail and not args.no_qr_retry:
            notes.append(f"¹ {base}: iSAM2 with its default Cholesky factorization fails: {peer_fail.rstrip('.')}; "
                         "the figures marked ¹ are a second run with ISAM2Params factorization QR")
            mark = " ¹"
            print(f"{base}: iSAM2 failed ({peer_fail}); again with QR …", file=sys.stderr, flush=True)
            peer, peer_rss, peer_chi2, peer_fail = isam2_3d(args, path, "qr")
        rows.append((base, runs, optimum, peer, peer_rss, peer_chi2, peer_fail, mark))
        print(f"done {name}", file=sys.stderr, flush=True)

    ms = lambda r: f"{r['p99_us'] / 1e3:.1f} / {r['max_us'] / 1e3:.1f}"
    print("| dataset | slamd total s | iSAM2 total s | ratio slamd/iSAM2 | slamd final χ² | iSAM2 final χ² (slamd eval) "
          "| batch optimum χ² | slamd worst sampled prefix ratio | slamd p99 / max per keyframe (ms) "
          "| iSAM2 p99 / max per keyframe (ms) | switched off | peak RSS slamd / iSAM2 MiB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for base, runs, optimum, peer, peer_rss, peer_chi2, peer_fail, mark in rows:
        for label, (m, rss) in runs.items():
            worst = m["prefix_run"]["worst_prefix_ratio"]
            worst = "–" if worst is None else f"{worst:.3f}"
            if peer_fail:
                p_secs = p_chi2 = p_ms = f"fails ({peer_fail})"
                ratio, p_rss = "–", "–"
            else:
                p_secs, p_chi2, p_ms = f"{peer['total_s']:.2f}{mark}", f"{peer_chi2:.3f}{mark}", ms(peer) + mark
                ratio, p_rss = f"{m['total_s'] / peer['total_s']:.3f}{mark}", f"{peer_rss:.0f}{mark}"
            print(f"| {base}{' ' + label if label else ''} | {m['total_s']:.2f} | {p_secs} | {ratio} | {m['chi2']:.3f} | {p_chi2} "
                  f"| {optimum:.3f} | {worst} | {ms(m)} | {p_ms} | {m['switched_off']} | {rss:.0f} / {p_rss} |")
    print()
    print("- slamd rows: `slamd replay FILE --embedded --json` (outlier filter on, the default) and the same with `--no-filter`; "
          "worst sampled prefix ratio from a separate, untimed run with `--check-prefixes 5` added.")
    print(f"- iSAM2: ISAM2Params defaults (factorization {args.isam2_factorization.upper()} unless marked), "
          "one update() + calculateEstimate() per keyframe; it runs once per file and both rows of a file show that run.")
    for n in notes:
        print(n)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--3d", dest="three_d", action="store_true",
                    help="the 3-D table: FILEs (default: " + ", ".join(DEFAULT3) + ") under DATASETS/3d")
    ap.add_argument("--peer-timeout", type=float, default=0, metavar="S",
                    help="give up on iSAM2 after S seconds, reading the file included, and report the "
                         "keyframe it had reached (default 0: never)")
    ap.add_argument("--isam2-factorization", choices=["cholesky", "qr"], default="cholesky",
                    help="3-D: ISAM2Params factorization (default: GTSAM's default, cholesky)")
    ap.add_argument("--no-qr-retry", action="store_true",
                    help="3-D: report iSAM2 as failing when Cholesky finds the system indeterminate "
                         "(default: run that file again with QR and mark its figures)")
    ap.add_argument("--isam2-child", help=argparse.SUPPRESS)
    ap.add_argument("--isam2-child3", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.isam2_child3:
        try:
            result, stats = isam2_replay3(args.isam2_child3, args.isam2_factorization)
        except Exception as e:
            from peer_gtsam import first_paragraph  # GTSAM's messages run to pages

            print(str(e) if isinstance(e, Isam2Failed) else first_paragraph(e), file=sys.stderr)
            return 1
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
            for k in sorted(result.keys()):
                p = result.atPose3(k)
                t, q = p.translation(), p.rotation().toQuaternion()
                f.write(" ".join([str(k)] + [repr(float(v)) for v in (t[0], t[1], t[2], q.x(), q.y(), q.z(), q.w())]) + "\n")
        stats["poses"] = f.name
        print(json.dumps(stats))
        return
    if args.three_d:
        return table_3d(args)
    if args.isam2_child:
        estimate, stats = isam2_replay(args.isam2_child)
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
            for k in sorted(estimate):
                p = estimate[k]
                f.write(f"{k} {p.x()!r} {p.y()!r} {p.theta()!r}\n")
        stats["poses"] = f.name
        print(json.dumps(stats))
        return
    rows = []
    for name in args.files or DEFAULT:
        path = name if os.path.exists(name) else os.path.join(DATA, name)
        out, mine_rss = run_child([args.slamd, "replay", path, "--embedded", "--json"])
        mine = json.loads(out)
        try:
            out, peer_rss = run_child([sys.executable, __file__, "--isam2-child", path],
                                      timeout=args.peer_timeout)
        except ChildFailed as e:
            rows.append((os.path.basename(path), mine, mine_rss, None, str(e), None))
            continue
        peer = json.loads(out)
        scored = json.loads(subprocess.run([args.slamd, "eval", path, peer["poses"], "--json"], check=True, capture_output=True, text=True).stdout)
        os.unlink(peer["poses"])
        rows.append((os.path.basename(path), mine, mine_rss, peer, scored["chi2"], peer_rss))
        print(f"done {name}", file=sys.stderr)
    print("| dataset | slamd total s | iSAM2 total s | ratio | slamd p50 / p99 / max µs | iSAM2 p50 / p99 / max µs | slamd final χ² | iSAM2 final χ² | peak RSS slamd / GTSAM MiB |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, m, mrss, p, pchi2, prss in rows:
        mine = f"{m['p50_us']:.0f} / {m['p99_us']:.0f} / {m['max_us']:.0f}"
        if p is None:  # pchi2 holds why iSAM2 failed
            print(f"| {name} | {m['total_s']:.2f} | {pchi2} | – | {mine} | – | {m['chi2']:.3f} | – | {mrss:.0f} / – |")
            continue
        print(f"| {name} | {m['total_s']:.2f} | {p['total_s']:.2f} | {m['total_s'] / p['total_s']:.3f} "
              f"| {mine} | {p['p50_us']:.0f} / {p['p99_us']:.0f} / {p['max_us']:.0f} "
              f"| {m['chi2']:.3f} | {pchi2:.3f} | {mrss:.0f} / {prss:.0f} |")


if __name__ == "__main__":
    sys.exit(main())
