"""GTSAM's graduated non-convexity (GncLMOptimizer, truncated least squares)
on a whole graph file, for the bench scripts that set slamd's filter beside
it.

`gnc(path, timeout)` converts any file slamd reads to g2o with its
dead-reckoned vertices (`slamd solve FILE --formulation odometry --out
X.g2o`), builds GTSAM's graph with the information as slamd and g2o mean
it (peer_gtsam.read_3d in 3-D: GTSAM's readG2o weighs rotation 4× too
much), marks the odometry (|i − j| = 1) as known inliers, starts from the
dead reckoning in 2-D and from GTSAM's chordal initialisation in 3-D, and
runs GNC in a child process. It returns the poses file (`id x y theta`, in
3-D `id x y z qx qy qz qw`), the loop closures it holds off (weight below
0.5, as slamd counts a switch) and its seconds, or a reason.
"""
import multiprocessing, os, queue as queue_module, subprocess, tempfile, time

from common import BIN
from peer_gtsam import pose2_graph, pose3_graph, read_3d, read_g2o


def _child(path, three, out, answer):
    try:
        import gtsam

        if three:
            vertices, edges = read_3d(path)
            graph = pose3_graph(vertices, edges)
        else:
            vertices, edges = read_g2o(path)
            graph = pose2_graph(vertices, edges)
        # the odometry, and the prior after the edges
        known = [n for n, (i, j, *_) in enumerate(edges) if abs(i - j) == 1]
        known.append(len(edges))
        loops = len(edges) + 1 - len(known)
        t0 = time.perf_counter()
        if three:
            initial = gtsam.InitializePose3.initialize(graph)
        else:
            initial = gtsam.Values()
            for k, p in vertices.items():
                initial.insert(k, gtsam.Pose2(*p))
        params = gtsam.GncLMParams()
        params.setKnownInliers(known)
        optimizer = gtsam.GncLMOptimizer(graph, initial, params)
        result = optimizer.optimize()
        seconds = time.perf_counter() - t0
        weights = optimizer.getWeights()
        off = sum(1 for n in range(len(edges)) if weights[n] < 0.5)
        with open(out, "w") as f:
            for k in sorted(result.keys()):
                if three:
                    p = result.atPose3(k)
                    t, q = p.translation(), p.rotation().toQuaternion()
                    values = (t[0], t[1], t[2], q.x(), q.y(), q.z(), q.w())
                else:
                    p = result.atPose2(k)
                    values = (p.x(), p.y(), p.theta())
                f.write(" ".join([str(k)] + [repr(float(v)) for v in values]) + "\n")
        answer.put({"seconds": seconds, "off": off, "loop_closures": loops, "poses": out})
    except Exception as e:
        answer.put({"reason": f"{type(e).__name__}: {' '.join(str(e).split())[:120]}"})


def gnc(path, timeout, binary=BIN):
    """GNC on `path` (see the module): a dict with `poses`, `off`,
    `loop_closures` and `seconds`, or with `reason`."""
    tmp = tempfile.mkdtemp(prefix="slamd-gnc-")
    g2o = os.path.join(tmp, "dead-reckoned.g2o")
    r = subprocess.run([binary, "solve", path, "--formulation", "odometry", "--out", g2o, "--json"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        return {"reason": (r.stderr.strip().splitlines() or ["slamd refused it"])[-1]}
    three = open(g2o).readline().startswith("VERTEX_SE3")
    ctx = multiprocessing.get_context("fork")
    answer = ctx.Queue()
    child = ctx.Process(target=_child, args=(g2o, three, os.path.join(tmp, "gnc.txt"), answer))
    child.start()
    deadline = time.monotonic() + timeout
    result = None
    while result is None:
        try:
            result = answer.get(timeout=1)
        except queue_module.Empty:
            if not child.is_alive():
                result = {"reason": f"GTSAM died (exit code {child.exitcode})"}
            elif time.monotonic() > deadline:
                result = {"reason": f"not done in {timeout:g} s"}
    if child.is_alive():
        child.kill()
    child.join()
    return result
