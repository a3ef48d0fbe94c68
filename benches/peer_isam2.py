#!/usr/bin/env python3
"""slamd's online replay against GTSAM's iSAM2, in one run.

    cargo build --release --bin slamd
    pip install gtsam
    python3 benches/peer_isam2.py [FILE ...]

Both stream the same edges in time order (sorted by max(i, j), then
min(i, j); newer-id-first edges inverted with their information kept) and
produce a whole estimate after every keyframe: slamd's snapshot, and iSAM2's
update() followed by calculateEstimate(). Latency per keyframe runs from the
arrival of its edges to the estimate; each side also ends with its final
answer (slamd: a last re-solve; iSAM2: its last estimate), scored by
`slamd eval` with g2o's chi2. Peak RSS is read for each side as a child
process.
"""
import argparse, json, math, os, subprocess, sys, tempfile, time

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("SLAMD_DATASETS") or os.path.normpath(os.path.join(HERE, "..", "..", "shared", "datasets"))
DEFAULT = ["manhattanolson3500_g2oversion.g2o", "city10000.g2o", "w10000.graph"]


def read_graph(path):
    """Edges (i, j, x, y, theta, info6 in g2o order), i < j."""
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
        if i > j:
            c, s = math.cos(th), math.sin(th)
            i, j, x, y, th = j, i, -(c * x + s * y), -(-s * x + c * y), -th
        edges.append((i, j, x, y, th, info))
    edges.sort(key=lambda e: (e[1], e[0]))
    return edges


def isam2_replay(path):
    import gtsam
    import numpy as np

    edges = read_graph(path)
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    estimate = {0: gtsam.Pose2()}
    latencies, by_key = [], {}
    for e in edges:
        by_key.setdefault(e[1], []).append(e)
    start = time.perf_counter()
    first = True
    for k in sorted(by_key):
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
            if j not in estimate and not values.exists(j) and i in estimate:
                values.insert(j, estimate[i].compose(z))
        isam.update(graph, values)
        result = isam.calculateEstimate()
        estimate = {key: result.atPose2(key) for key in result.keys()}
        latencies.append((time.perf_counter() - t0) * 1e6)
    total = time.perf_counter() - start
    latencies.sort()
    pct = lambda q: latencies[round((len(latencies) - 1) * q)]
    return estimate, {"p50_us": pct(0.5), "p99_us": pct(0.99), "max_us": latencies[-1], "total_s": total}


def run_child(argv):
    """Runs argv, returns (stdout, peak RSS in MiB of that very child)."""
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{argv[0]} exited with {p.returncode}")
    return out, usage.ru_maxrss / 1024.0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--slamd", default=os.path.join(HERE, "..", "target", "release", "slamd"))
    ap.add_argument("--isam2-child", help=argparse.SUPPRESS)
    args = ap.parse_args()
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
        out, peer_rss = run_child([sys.executable, __file__, "--isam2-child", path])
        peer = json.loads(out)
        scored = json.loads(subprocess.run([args.slamd, "eval", path, peer["poses"], "--json"], check=True, capture_output=True, text=True).stdout)
        os.unlink(peer["poses"])
        rows.append((os.path.basename(path), mine, mine_rss, peer, scored["chi2"], peer_rss))
        print(f"done {name}", file=sys.stderr)
    print("| dataset | slamd total s | iSAM2 total s | ratio | slamd p50 / p99 / max µs | iSAM2 p50 / p99 / max µs | slamd final χ² | iSAM2 final χ² | peak RSS slamd / GTSAM MiB |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, m, mrss, p, pchi2, prss in rows:
        print(f"| {name} | {m['total_s']:.2f} | {p['total_s']:.2f} | {m['total_s'] / p['total_s']:.3f} "
              f"| {m['p50_us']:.0f} / {m['p99_us']:.0f} / {m['max_us']:.0f} | {p['p50_us']:.0f} / {p['p99_us']:.0f} / {p['max_us']:.0f} "
              f"| {m['chi2']:.3f} | {pchi2:.3f} | {mrss:.0f} / {prss:.0f} |")


if __name__ == "__main__":
    sys.exit(main())
