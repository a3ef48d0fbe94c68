#!/usr/bin/env python3
"""slamd against GTSAM's Levenberg–Marquardt on the same files, in one run.

    cargo build --release --bin slamd
    pip install gtsam
    python3 benches/peer_gtsam.py [--repeat 3]           # 2-D table
    python3 benches/peer_gtsam.py --3d [--repeat 3]      # 3-D table
    python3 benches/peer_gtsam.py [--3d] --files NAME... # a subset of either

Both results are scored by `slamd eval` (g2o's χ², ATE after rigid
alignment), so the figures are comparable. Times exclude file I/O on both
sides; each figure is the best of --repeat runs.

Both sides get every edge as written, BetweenFactor(i, j, Z) whichever id
is newer (docs/design.md, "Edge direction").

2-D: GTSAM starts from the file's own initial guess, as a GTSAM user would;
slamd starts from nothing (two-stage linear solve, then its polish).

3-D (the files under DATASETS/3d): GTSAM's LM starts from GTSAM's own chordal
initialisation, `InitializePose3.initialize` on the graph plus a tight
PriorFactorPose3 on the first key (as in GTSAM's example
Pose3SLAMExample_initializePose3Chordal.py); its time is initialisation + LM.
slamd runs `solve --polish` (3-D detected from the file).

GTSAM's 3-D graph is built here, not with `gtsam.readG2o`, which (GTSAM 4.3)
reads the poses right but not the information: it takes that of
`EDGE_SE3:QUAT` as written, only permuted to GTSAM's [rotation; translation]
order, though GTSAM's rotation error is the rotation vector and g2o's the
quaternion vector (half of it), so rotation weighs 4× more than in the χ² both
are scored on; and it takes HOG-Man `EDGE3` information (over x y z roll
pitch yaw) as if it were already in GTSAM's order, swapping the translation
and rotation blocks. Here a g2o information Ω over [Δt, Δq_xyz] becomes
D Ω D, D = diag(1, 1, 1, ½, ½, ½), permuted to [rotation; translation]; a
HOG-Man Ω_rpy becomes slamd's Ω_q = diag(1, 1, 1, 2, 2, 2) Ω_rpy
diag(1, 1, 1, 2, 2, 2) and then the same, i.e. Ω_rpy permuted.

cubicle.g2o has 5021 edges whose information is not positive definite: slamd
solves it with --skip-invalid; GTSAM gets every edge of the file, as readG2o
would give it (noiseModel.Gaussian.Information does not refuse those
matrices, it keeps what its Cholesky makes of them), and its poses, if any,
are scored on a copy without those edges, the graph slamd solved. A GTSAM
run that raises, returns non-finite poses or exceeds --peer-timeout is
reported as "fails (reason)" beside slamd's result.
"""
import argparse, json, math, multiprocessing, os, subprocess, sys, tempfile, time

from common import BIN, DATA, positive_definite, upper, slamd

CASES = [  # file, optimum χ², ground truth
    ("manhattanolson3500_g2oversion.g2o", 146.077, "groundtruth/manhattanolson3500_nodes_groundtruth.dat"),
    ("city10000.g2o", 511.985, "groundtruth/city10000_groundtruth_isam.txt"),
    ("intel_sesync.g2o", 45.005, None),
    ("input_intel_g2o.g2o", 215.830, None),
    ("mit_killian.g2o", 41.163, None),
    ("ring.g2o", 11.163, "groundtruth/ring_groundtruth.g2o"),
    ("ringcity.g2o", 262.818, "groundtruth/ringcity_groundtruth.g2o"),
]

CASES3 = [  # file under 3d/, ground truth under 3d/, extra `slamd solve` flags
    ("sphere2500.g2o", "groundtruth/sphere2500_groundtruth_isam.txt", []),
    ("torus3d.g2o", None, []),
    ("parking-garage.g2o", None, []),
    ("cubicle.g2o", None, ["--skip-invalid"]),
    ("smallgrid3d.g2o", None, []),
    ("tinygrid3d.g2o", None, []),
    ("sphere_bignoise_vertex3.g2o", None, []),
    ("sphere_smallnoise.graph", None, []),
    ("sphere_mednoise.graph", None, []),
    ("sphere_bignoise.graph", None, []),
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
            edges.append((i, j, x, y, th, info))
    return vertices, edges


def pose2_graph(vertices, edges):
    """GTSAM's graph of read_g2o's `edges`, every one as written, and a
    tight prior on the first vertex."""
    import gtsam
    import numpy as np

    graph = gtsam.NonlinearFactorGraph()
    for i, j, x, y, th, I in edges:
        omega = np.array([[I[0], I[1], I[2]], [I[1], I[3], I[4]], [I[2], I[4], I[5]]])
        graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(x, y, th), gtsam.noiseModel.Gaussian.Information(omega)))
    first = min(vertices)
    graph.add(gtsam.PriorFactorPose2(first, gtsam.Pose2(*vertices[first]), gtsam.noiseModel.Diagonal.Sigmas(np.array([1e-6, 1e-6, 1e-8]))))
    return graph


def pose3_graph(vertices, edges):
    """GTSAM's graph of read_3d's `edges`, every one as written, and a
    tight prior on the first vertex."""
    import gtsam
    import numpy as np

    graph = gtsam.NonlinearFactorGraph()
    for i, j, z, omega in edges:
        graph.add(gtsam.BetweenFactorPose3(i, j, z, gtsam.noiseModel.Gaussian.Information(omega)))
    first = min(vertices)
    prior = gtsam.noiseModel.Diagonal.Variances(np.array([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4]))
    graph.add(gtsam.PriorFactorPose3(first, vertices[first], prior))
    return graph


def run_gtsam(path, repeat):
    import gtsam

    vertices, edges = read_g2o(path)
    graph = pose2_graph(vertices, edges)
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


def gtsam_information(omega_q):
    """g2o/slamd information over [Δt, Δq_xyz] → GTSAM's over [rotation vector; translation].

    Δq_xyz ≈ ½ rotation vector, so Ω_rotvec = D Ω D with D = diag(1, 1, 1, ½, ½, ½),
    then the blocks swap to GTSAM's order."""
    import numpy as np

    d = np.array([1, 1, 1, 0.5, 0.5, 0.5])
    m = d[:, None] * omega_q * d[None, :]
    p = [3, 4, 5, 0, 1, 2]
    return m[np.ix_(p, p)]


def read_3d(path):
    """Vertices {id: Pose3} and edges [(i, j, Z, Ω in GTSAM's order)], as written, of a g2o or HOG-Man 3-D file."""
    import gtsam
    import numpy as np

    def quaternion_pose(v):
        x, y, z, qx, qy, qz, qw = map(float, v)
        n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        return gtsam.Pose3(gtsam.Rot3.Quaternion(qw / n, qx / n, qy / n, qz / n), gtsam.Point3(x, y, z))

    def rpy_pose(v):  # R = Rz(yaw) Ry(pitch) Rx(roll)
        x, y, z, roll, pitch, yaw = map(float, v)
        return gtsam.Pose3(gtsam.Rot3.Ypr(yaw, pitch, roll), gtsam.Point3(x, y, z))

    rpy_to_q = np.array([1, 1, 1, 2, 2, 2])  # slamd: Ω_q = D Ω_rpy D
    vertices, edges = {}, []
    for line in open(path):
        t = line.split()
        if not t or t[0].startswith("#"):
            continue
        if t[0] == "VERTEX_SE3:QUAT":
            vertices[int(t[1])] = quaternion_pose(t[2:9])
        elif t[0] == "VERTEX3":
            vertices[int(t[1])] = rpy_pose(t[2:8])
        elif t[0] == "EDGE_SE3:QUAT":
            omega = upper(list(map(float, t[10:31])), 6)
            edges.append((int(t[1]), int(t[2]), quaternion_pose(t[3:10]), gtsam_information(omega)))
        elif t[0] == "EDGE3":
            omega = upper(list(map(float, t[9:30])), 6)
            omega_q = rpy_to_q[:, None] * omega * rpy_to_q[None, :]
            edges.append((int(t[1]), int(t[2]), rpy_pose(t[3:9]), gtsam_information(omega_q)))
    return vertices, edges


def first_paragraph(e):
    """`Type: the first paragraph of the message`, on one line (GTSAM's messages run to pages)."""
    text = str(e).strip().split("\n\n")[0]
    return f"{type(e).__name__}: {' '.join(text.split())}"


def gtsam3_child(path, repeat, poses_path, queue):
    """Runs in a child process (so a hang can be timed out): chordal init + LM,
    best of `repeat`; writes the poses as `id x y z qx qy qz qw` and puts
    (seconds, iterations, None) or (None, None, reason) on `queue`."""
    try:
        import gtsam
        import numpy as np

        vertices, edges = read_3d(path)
        graph = pose3_graph(vertices, edges)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        best, result, iters = float("inf"), None, None
        for _ in range(repeat):
            t0 = time.perf_counter()
            try:
                initial = gtsam.InitializePose3.initialize(graph)
            except Exception as e:
                queue.put((None, None, f"chordal init raised {first_paragraph(e)}"))
                return
            bad = [k for k in initial.keys() if not np.all(np.isfinite(initial.atPose3(k).matrix()))]
            if bad:
                queue.put((None, None, f"chordal init gave {len(bad)} non-finite poses of {initial.size()}"))
                return
            try:
                opt = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
                out = opt.optimize()
            except Exception as e:
                queue.put((None, None, f"LM raised {first_paragraph(e)}"))
                return
            secs = time.perf_counter() - t0
            if secs < best:
                best, result, iters = secs, out, opt.iterations()
        bad = [k for k in result.keys() if not np.all(np.isfinite(result.atPose3(k).matrix()))]
        if bad:
            queue.put((None, None, f"LM gave {len(bad)} non-finite poses of {result.size()}"))
            return
        with open(poses_path, "w") as f:
            for k in sorted(result.keys()):
                p = result.atPose3(k)
                t, q = p.translation(), p.rotation().toQuaternion()
                f.write(" ".join([str(k)] + [repr(float(v)) for v in (t[0], t[1], t[2], q.x(), q.y(), q.z(), q.w())]) + "\n")
        queue.put((best, iters, None))
    except Exception as e:
        queue.put((None, None, first_paragraph(e)))


def run_gtsam3(path, repeat, timeout, poses_path):
    """(seconds, iterations, None) or (None, None, reason); the poses land in poses_path."""
    import queue as queue_module

    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=gtsam3_child, args=(path, repeat, poses_path, queue))
    child.start()
    deadline = time.monotonic() + timeout * repeat if timeout > 0 else math.inf
    while True:
        try:
            answer = queue.get(timeout=1)
            child.join(timeout=10)
            break
        except queue_module.Empty:
            if not child.is_alive():
                try:
                    answer = queue.get(timeout=1)
                except queue_module.Empty:
                    answer = None, None, f"GTSAM process died (exit code {child.exitcode})"
                break
            if time.monotonic() > deadline:
                answer = None, None, f"timed out after {timeout:g} s per run"
                break
    if child.is_alive():
        child.kill()
    child.join()
    return answer


def without_invalid_edges(path):
    """A temp copy of a g2o 3-D graph without the edges whose information is
    not positive definite (what --skip-invalid skips) and the count dropped."""
    dropped = 0
    with tempfile.NamedTemporaryFile("w", suffix=".g2o", delete=False) as f:
        for line in open(path):
            t = line.split()
            if t and t[0] == "EDGE_SE3:QUAT" and not positive_definite(upper(list(map(float, t[10:31])), 6)):
                dropped += 1
                continue
            f.write(line)
    return f.name, dropped


def table_2d(args):
    cases = [c for c in CASES if not args.files or c[0] in args.files]
    rows = []
    for name, optimum, gt in cases:
        path = os.path.join(DATA, name)
        gt_args = ["--ground-truth", os.path.join(DATA, gt)] if gt else []
        runs = [slamd("solve", path, "--polish", "--json", *gt_args, binary=args.slamd) for _ in range(args.repeat)]
        mine = min(runs, key=lambda r: r["seconds"])
        result, secs, iters = run_gtsam(path, args.repeat)
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
            for k in sorted(result.keys()):
                p = result.atPose2(k)
                f.write(f"{k} {p.x()!r} {p.y()!r} {p.theta()!r}\n")
        peer = slamd("eval", path, f.name, "--json", *gt_args, binary=args.slamd)
        os.unlink(f.name)
        rows.append((name, optimum, mine, peer, secs, iters))

    fmt_ate = lambda a: "–" if a is None else f"{a:.3f}"
    print("| dataset | optimum χ² | slamd χ² | GTSAM LM χ² | slamd ATE (m) | GTSAM ATE (m) | slamd s | GTSAM s | time slamd/GTSAM |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, optimum, mine, peer, secs, iters in rows:
        print(f"| {name} | {optimum:.3f} | {mine['chi2']:.3f} | {peer['chi2']:.3f} | {fmt_ate(mine['ate'])} | {fmt_ate(peer['ate'])} "
              f"| {mine['seconds']:.4f} | {secs:.4f} ({iters} it) | {mine['seconds'] / secs:.2f} |")


def slamd_or_reason(binary, args):
    """slamd's JSON, or the first line of its complaint."""
    try:
        return slamd(*args, binary=binary), None
    except subprocess.CalledProcessError as e:
        return None, (e.stderr.strip().splitlines() or [f"exit code {e.returncode}"])[0]


def table_3d(args):
    cases = [c for c in CASES3 if not args.files or c[0] in args.files]
    rows, notes, footnote = [], [], None
    for name, gt, flags in cases:
        path = os.path.join(DATA, "3d", name)
        gt_args = ["--ground-truth", os.path.join(DATA, "3d", gt)] if gt else []
        print(f"{name}: slamd …", file=sys.stderr, flush=True)
        mine, mine_fail = None, None
        for _ in range(args.repeat):
            r, mine_fail = slamd_or_reason(args.slamd, ["solve", path, "--polish", "--json"] + flags + gt_args)
            if r is None:
                break
            if mine is None or r["seconds"] < mine["seconds"]:
                mine = r
        if mine_fail:
            mine = None
            notes.append(f"{name}: slamd fails: {mine_fail}")
        elif mine["skipped_lines"]["count"]:
            footnote = (f"¹ {name}: slamd solved it with {' '.join(flags)}, skipping {mine['skipped_lines']['count']} lines "
                        f"(first: {mine['skipped_lines']['first'][0]}); GTSAM got the whole file")

        print(f"{name}: GTSAM …", file=sys.stderr, flush=True)
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as f:
            poses = f.name
        secs, iters, peer_fail = run_gtsam3(path, args.repeat, args.peer_timeout, poses)
        peer = None
        if peer_fail is None:
            peer, eval_fail = slamd_or_reason(args.slamd, ["eval", path, poses, "--json"] + gt_args)
            if peer is None and "--skip-invalid" in flags:
                clean, dropped = without_invalid_edges(path)
                peer, eval_fail2 = slamd_or_reason(args.slamd, ["eval", clean, poses, "--json"] + gt_args)
                os.unlink(clean)
                notes.append(f"{name}: `slamd eval` refuses the graph ({eval_fail}); GTSAM's poses are scored on a copy without "
                             f"the {dropped} edges whose information is not positive definite"
                             + (f" ({peer['edges']} edges, as slamd solved)" if peer and mine and peer["edges"] == mine["edges"] else "")
                             + (f"; that fails too: {eval_fail2}" if peer is None else ""))
            elif peer is None:
                notes.append(f"{name}: `slamd eval` of GTSAM's poses fails: {eval_fail}")
        else:
            notes.append(f"{name}: GTSAM fails: {peer_fail}")
        os.unlink(poses)
        rows.append((name, mine, mine_fail, peer, peer_fail, secs, iters))

    fmt_ate = lambda r: "–" if r is None or r["ate"] is None else f"{r['ate']:.3f}"
    fails = lambda why: f"fails ({why})"
    print("| dataset | slamd χ² | GTSAM χ² (slamd eval) | ratio slamd/GTSAM χ² | slamd ATE (m) | GTSAM ATE (m) "
          "| slamd s | GTSAM s (init + LM, iterations) | time slamd/GTSAM |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, mine, mine_fail, peer, peer_fail, secs, iters in rows:
        star = " ¹" if mine and mine["skipped_lines"]["count"] else ""
        m_chi2 = f"{mine['chi2']:.3f}{star}" if mine else fails(mine_fail)
        m_secs = f"{mine['seconds']:.4f}" if mine else fails(mine_fail)
        if peer_fail:
            p_chi2 = p_ate = p_secs = fails(peer_fail)
            ratio = t_ratio = "–"
        else:
            p_chi2 = f"{peer['chi2']:.3f}" if peer else "– (eval fails)"
            p_ate = fmt_ate(peer)
            p_secs = f"{secs:.4f} ({iters} it)"
            ratio = f"{mine['chi2'] / peer['chi2']:.4f}" if mine and peer else "–"
            t_ratio = f"{mine['seconds'] / secs:.2f}" if mine else "–"
        print(f"| {name} | {m_chi2} | {p_chi2} | {ratio} | {fmt_ate(mine)} | {p_ate} | {m_secs} | {p_secs} | {t_ratio} |")
    print()
    print(f"- GTSAM: LM (at most 100 iterations) from `InitializePose3.initialize` (chordal), edges as written; best of {args.repeat}")
    if footnote:
        print(footnote)
    for n in notes:
        print("- " + n)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--3d", dest="three_d", action="store_true", help="the 3-D files under DATASETS/3d instead of the 2-D ones")
    ap.add_argument("--files", nargs="+", metavar="NAME", help="only these files of the table (names as listed in CASES/CASES3)")
    ap.add_argument("--peer-timeout", type=float, default=600, metavar="S",
                    help="3-D: give up on GTSAM after S seconds per run, its graph building included (0: never); default 600")
    args = ap.parse_args()
    if args.files:
        known = {c[0] for c in (CASES3 if args.three_d else CASES)}
        unknown = [n for n in args.files if n not in known]
        if unknown:
            ap.error(f"not in the {'3-D' if args.three_d else '2-D'} table: {', '.join(unknown)} (known: {', '.join(sorted(known))})")
    (table_3d if args.three_d else table_2d)(args)


if __name__ == "__main__":
    sys.exit(main())
