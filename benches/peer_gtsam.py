#!/usr/bin/env python3
"""slamd against GTSAM's Levenberg–Marquardt on the same files, in one run.

    cargo build --release --bin slamd
    pip install gtsam
    python3 benches/peer_gtsam.py [--repeat 3]

Both results are scored by `slamd eval` (g2o's χ², ATE after rigid
alignment), so the figures are comparable. GTSAM gets the same graph slamd
solves (newer-id-first edges inverted, information kept; docs/design.md,
"Scoring: χ² and ATE") and starts from the file's own initial guess, as a
GTSAM user would; slamd starts from nothing (two-stage linear solve, then
its polish). Times exclude file I/O on both sides; each figure is the best
of --repeat runs.
"""
import argparse, json, math, os, subprocess, sys, tempfile, time

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("SLAMD_DATASETS") or os.path.normpath(os.path.join(HERE, "..", "..", "shared", "datasets"))
CASES = [  # file, optimum χ², ground truth
    ("manhattanolson3500_g2oversion.g2o", 146.077, "groundtruth/manhattanolson3500_nodes_groundtruth.dat"),
    ("city10000.g2o", 511.985, "groundtruth/city10000_groundtruth_isam.txt"),
    ("intel_sesync.g2o", 45.005, None),
    ("input_intel_g2o.g2o", 215.830, None),
    ("mit_killian.g2o", 39.880, None),
    ("ring.g2o", 11.163, "groundtruth/ring_groundtruth.g2o"),
    ("ringcity.g2o", 262.818, "groundtruth/ringcity_groundtruth.g2o"),
]


def read_g2o(path):
    vertices, edges = {}, []
    for line in open(path):
        t = line.split()
        if not t:
            continue
        if t[0] == "VERTEX_SE2":
            vertices[int(t[1])] = tuple(map(float, t[2:5]))
        elif t[0] == "EDGE_SE2":
            i, j = int(t[1]), int(t[2])
            x, y, th = map(float, t[3:6])
            info = list(map(float, t[6:12]))
            if i > j:  # the convention slamd and the published optima use
                c, s = math.cos(th), math.sin(th)
                i, j, x, y, th = j, i, -(c * x + s * y), -(-s * x + c * y), -th
            edges.append((i, j, x, y, th, info))
    return vertices, edges


def run_gtsam(path, repeat):
    import gtsam
    import numpy as np

    vertices, edges = read_g2o(path)
    graph = gtsam.NonlinearFactorGraph()
    for i, j, x, y, th, I in edges:
        omega = np.array([[I[0], I[1], I[2]], [I[1], I[3], I[4]], [I[2], I[4], I[5]]])
        graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(x, y, th), gtsam.noiseModel.Gaussian.Information(omega)))
    first = min(vertices)
    graph.add(gtsam.PriorFactorPose2(first, gtsam.Pose2(*vertices[first]), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-6, 1e-6, 1e-8]))))
    initial = gtsam.Values()
    for k, p in vertices.items():
        initial.insert(k, gtsam.Pose2(*p))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    best, result = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        result = opt.optimize()
        best = min(best, time.perf_counter() - t0)
    return result, best, opt.iterations()


def slamd(binary, args):
    out = subprocess.run([binary] + args, check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=os.path.join(HERE, "..", "target", "release", "slamd"))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    for name, optimum, gt in CASES:
        path = os.path.join(DATA, name)
        gt_args = ["--ground-truth", os.path.join(DATA, gt)] if gt else []
        runs = [slamd(args.slamd, ["solve", path, "--polish", "--json"] + gt_args) for _ in range(args.repeat)]
        mine = min(runs, key=lambda r: r["seconds"])
        result, secs, iters = run_gtsam(path, args.repeat)
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
            for k in sorted(result.keys()):
                p = result.atPose2(k)
                f.write(f"{k} {p.x()!r} {p.y()!r} {p.theta()!r}\n")
        peer = slamd(args.slamd, ["eval", path, f.name, "--json"] + gt_args)
        os.unlink(f.name)
        rows.append((name, optimum, mine, peer, secs, iters))

    fmt_ate = lambda a: "–" if a is None else f"{a:.3f}"
    print("| dataset | optimum χ² | slamd χ² | GTSAM LM χ² | slamd ATE (m) | GTSAM ATE (m) | slamd s | GTSAM s | time slamd/GTSAM |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, optimum, mine, peer, secs, iters in rows:
        print(f"| {name} | {optimum:.3f} | {mine['chi2']:.3f} | {peer['chi2']:.3f} | {fmt_ate(mine['ate'])} | {fmt_ate(peer['ate'])} "
              f"| {mine['seconds']:.4f} | {secs:.4f} ({iters} it) | {mine['seconds'] / secs:.2f} |")


if __name__ == "__main__":
    sys.exit(main())
