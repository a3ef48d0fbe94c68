#!/usr/bin/env python3
"""Robustness: wrong loop closures, filtered online, in one run.

    cargo build --release --bin slamd
    python3 benches/outliers.py [--datasets manhattan city intel ringcity sphere]
                                [--kinds random local random-grouped local-grouped]
                                [--counts 100 1000 4000] [--peers --peer-timeout 600]

Paper B's protocol, extended (docs/design.md, "Robust kernels and
switches"). ../shared/tools/add_outliers.py injects Vertigo-style loop
closures (seed --seed; benches/add_outliers3.py into Sphere2500, the
`sphere` dataset, for which no peer runs); `slamd replay --embedded`
streams the spoiled file in time order (max(i, j)), one snapshot per
keyframe, the filter on with its defaults. Per run:

- precision / recall of the injected edges (an edge counts as caught when
  its final switch is < 0.5; `rejected_edges` in slamd's JSON);
- ATE against ground truth next to the outlier-free replay's ATE;
- chi2 over the true edges (the outlier-free file scored by `slamd eval`)
  relative to the outlier-free optimum;
- total replay time, the outlier-free replay's in the same run and their
  ratio, and p99 and max latency per keyframe;
- keyframes from a loop closure's arrival to the filter's decision on it
  (median / 99th percentile / largest), where slamd reports it;
- the most snapshots any wrong loop closure weighed in with (its switch at
  least 0.5 in the published estimate), and how many wrong ones ever did. A replay
  streams as fast as the publishing engine takes keyframes (unless
  `--rate` paces it), so these measure how far the filter's judge runs
  behind it.

With --peers, GTSAM runs on the same spoiled files from the odometry
guess, each under --peer-timeout seconds, and is scored the same way:
GncOptimizer (Levenberg–Marquardt inside, truncated least squares,
odometry known inliers; a weight below 0.5 is a rejection) and
Levenberg–Marquardt with DCS at slamd's Φ on every loop closure (a switch
below 0.5 at its optimum is a rejection).
"""
import argparse, json, math, os, subprocess, sys, tempfile, time

from common import BIN, DATA, HERE, slamd

TOOL = os.path.join(DATA, "..", "tools", "add_outliers.py")
TOOL3 = os.path.join(HERE, "add_outliers3.py")
DATASETS = {  # name: (file, ground truth)
    "manhattan": ("manhattanolson3500_g2oversion.g2o", "groundtruth/manhattanolson3500_groundtruth_isam.txt"),
    "city": ("city10000.g2o", "groundtruth/city10000_groundtruth_isam.txt"),
    "intel": ("intel_sesync.g2o", None),
    "ringcity": ("ringcity.g2o", "groundtruth/ringcity_groundtruth.g2o"),
    "sphere": ("3d/sphere2500.g2o", "3d/groundtruth/sphere2500_groundtruth_isam.txt"),
}
THREE_D = {"sphere"}  # spoiled by benches/add_outliers3.py; no peers


def weighed_in(r, injected):
    """The most snapshots a wrong loop closure weighed in (switch ≥ 0.5) and how many ever did."""
    counts = r.get("weighted_snapshots")
    if counts is None:
        return "–"
    wrong = [counts[e] for e in injected]
    return f"{max(wrong)} / {sum(1 for n in wrong if n > 0)}"


def score(binary, clean, poses, gt):
    args = ["eval", clean, poses, "--json"] + (["--ground-truth", gt] if gt else [])
    return slamd(*args, binary=binary)


PEER = """
import json, math, sys, time, gtsam, numpy as np
sys.path.insert(0, {here!r})
from peer_gtsam import read_g2o
vertices, edges = read_g2o({spoiled!r})
dcs = gtsam.noiseModel.mEstimator.DCS.Create({phi!r})
graph = gtsam.NonlinearFactorGraph()
known = []
plain = []  # each edge's factor without the kernel, to score switches by
for n, (i, j, x, y, th, I) in enumerate(edges):
    omega = np.array([[I[0], I[1], I[2]], [I[1], I[3], I[4]], [I[2], I[4], I[5]]])
    noise = gtsam.noiseModel.Gaussian.Information(omega)
    plain.append(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(x, y, th), noise))
    if {method!r} == "dcs" and j != i + 1:
        noise = gtsam.noiseModel.Robust.Create(dcs, noise)
    graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(x, y, th), noise))
    if j == i + 1:
        known.append(n)
first = min(vertices)
graph.add(gtsam.PriorFactorPose2(first, gtsam.Pose2(0, 0, 0), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-6, 1e-6, 1e-8]))))
known.append(len(edges))
# odometry guess
guess = {{first: gtsam.Pose2(0, 0, 0)}}
for i, j, x, y, th, I in sorted(e for e in edges if e[1] == e[0] + 1):
    if i in guess:
        guess[j] = guess[i].compose(gtsam.Pose2(x, y, th))
initial = gtsam.Values()
for k in vertices:
    initial.insert(k, guess.get(k, gtsam.Pose2(*vertices[k])))
t = time.perf_counter()
if {method!r} == "gnc":
    params = gtsam.GncLMParams()
    params.setKnownInliers(known)
    optimizer = gtsam.GncLMOptimizer(graph, initial, params)
    result = optimizer.optimize()
    weights = optimizer.getWeights()
    rejected = [n for n in range(len(edges)) if weights[n] < 0.5]
else:
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, gtsam.LevenbergMarquardtParams()).optimize()
    rejected = [n for n, (i, j, *_) in enumerate(edges)
                if j != i + 1 and dcs.weight(math.sqrt(2 * plain[n].error(result))) < 0.25]
secs = time.perf_counter() - t
with open({out!r}, "w") as f:
    for k in sorted(vertices):
        p = result.atPose2(k)
        f.write(f"{{k}} {{p.x()}} {{p.y()}} {{p.theta()}}\\n")
print(json.dumps({{"seconds": secs, "rejected": rejected}}))
"""


def peer(spoiled, method, timeout, phi=16.27 / 3):
    """GTSAM on `spoiled` in a child process: `gnc` (GncLMOptimizer, truncated
    least squares, odometry known inliers) or `dcs` (Levenberg–Marquardt with
    DCS at Φ on every loop closure), from the odometry guess. Returns
    (seconds, poses file, rejected edge indices) or None on failure or
    timeout. A loop closure counts as rejected at a GNC weight below 0.5 or
    a DCS weight s² below 0.25 (s < 0.5, as slamd counts)."""
    out = tempfile.mktemp(suffix=".txt")
    code = PEER.format(here=HERE, spoiled=spoiled, phi=phi, method=method, out=out)
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    if r.returncode != 0:
        print(r.stderr[-500:], file=sys.stderr)
        return None
    res = json.loads(r.stdout)
    return res["seconds"], out, set(res["rejected"])


def gnc(spoiled, timeout):
    """GTSAM's GNC on `spoiled` (see [`peer`]): (seconds, poses file) or None."""
    g = peer(spoiled, "gnc", timeout)
    return g and g[:2]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--datasets", nargs="+", default=list(DATASETS))
    ap.add_argument("--kinds", nargs="+", default=["random", "local", "random-grouped", "local-grouped"])
    ap.add_argument("--counts", nargs="+", type=int, default=[100, 1000, 4000])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--extra", nargs="*", default=[], help="more slamd replay flags, e.g. --kernel sc:1")
    ap.add_argument("--rate", type=float, help="keyframes per second (`slamd replay --rate`): the filter's "
                    "decisions at a robot's pace rather than as fast as the engine takes keyframes")
    ap.add_argument("--peers", action="store_true", help="GTSAM's GNC and DCS in its LM on the same files")
    ap.add_argument("--peer-timeout", type=float, default=600)
    args = ap.parse_args()
    if args.rate:
        args.extra += ["--rate", str(args.rate)]
    tmp = tempfile.mkdtemp(prefix="slamd-outliers-")
    print(f"slamd replay --embedded {' '.join(args.extra)} (filter defaults); seed {args.seed}")
    print("| dataset | outliers | precision | recall | ATE (m) | ATE clean (m) | χ² true / optimum | total (s) | clean (s) | total / clean | p99 (ms) | max (ms) | decided after (keyframes) | wrong ones weighed in: most snapshots / how many |"
          + (" GNC P / R | GNC ATE (m) | GNC χ² true / optimum | GNC (s) | LM+DCS P / R | LM+DCS ATE (m) | LM+DCS χ² true / optimum | LM+DCS (s) |" if args.peers else ""))
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" * 8 if args.peers else ""))
    for name in args.datasets:
        file, gt = DATASETS[name]
        clean = os.path.join(DATA, file)
        gt = os.path.join(DATA, gt) if gt else None
        optimum = slamd("solve", clean, "--polish", "--json", binary=args.slamd)["chi2"]
        gt_args = ["--ground-truth", gt] if gt else []
        base = slamd("replay", clean, "--embedded", "--json", "--weighted", *gt_args, *args.extra, binary=args.slamd)
        for kind in args.kinds:
            for count in args.counts:
                spoiled = os.path.join(tmp, f"{name}-{kind}-{count}.g2o")
                tool = TOOL3 if name in THREE_D else TOOL
                subprocess.run([sys.executable, tool, "-i", clean, "-o", spoiled, "--kind", kind,
                                "--count", str(count), "--seed", str(args.seed)], check=True, capture_output=True)
                side = json.load(open(spoiled + ".outliers.json"))
                injected = {o["edge_index"] for o in side["outliers"]}
                poses = spoiled + ".poses"
                r = slamd("replay", spoiled, "--embedded", "--json", "--weighted", "--out", poses, *gt_args, *args.extra,
                          binary=args.slamd)
                caught = injected & set(r["rejected_edges"])
                precision = len(caught) / max(1, len(r["rejected_edges"]))
                recall = len(caught) / len(injected)
                s = score(args.slamd, clean, poses, gt)
                ate = f"{r['ate']:.4f}" if r.get("ate") is not None else "–"
                ate0 = f"{base['ate']:.4f}" if base.get("ate") is not None else "–"
                row = (f"| {name} | {count} {kind} | {precision:.3f} | {recall:.3f} | {ate} | {ate0} | "
                       f"{s['chi2'] / optimum:.3f} | {r['total_s']:.2f} | {base['total_s']:.2f} | "
                       f"{r['total_s'] / base['total_s']:.2f} | {r['p99_us'] / 1e3:.1f} | {r['max_us'] / 1e3:.0f} | "
                       f"{' / '.join(map(str, (r.get('engine') or {}).get('decision_lag_keyframes') or ['–']))} | "
                       f"{weighed_in(r, injected)} |")
                if args.peers and name in THREE_D:
                    row += " – | – | – | – | – | – | – | – |"
                for method in ("gnc", "dcs") if args.peers and name not in THREE_D else ():
                    g = peer(spoiled, method, args.peer_timeout)
                    if g is None:
                        row += f" failed or timed out ({args.peer_timeout:.0f} s) | – | – | – |"
                        continue
                    secs, gposes, rejected = g
                    gs = score(args.slamd, clean, gposes, gt)
                    gate = f"{gs['ate']:.4f}" if gs.get("ate") is not None else "–"
                    caught = injected & rejected
                    row += (f" {len(caught) / max(1, len(rejected)):.3f} / {len(caught) / len(injected):.3f} | "
                            f"{gate} | {gs['chi2'] / optimum:.3f} | {secs:.1f} |")
                print(row, flush=True)


if __name__ == "__main__":
    sys.exit(main())
