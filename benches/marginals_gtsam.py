#!/usr/bin/env python3
"""slamd's marginal covariances against GTSAM's `Marginals`, in one run.

    cargo build --release --bin slamd
    pip install gtsam numpy
    python3 benches/marginals_gtsam.py [--files NAME...]

slamd solves each file (`solve --polish --out X.g2o --covariances X.cov`).
GTSAM then reads slamd's result (`readG2o` of X.g2o: the edges as slamd
holds them, the poses where slamd put them), adds a PriorFactorPose2 of σ
1e-6 on the first keyframe (slamd holds it fixed), and computes
`Marginals(graph, values).marginalCovariance(k)` for every keyframe at the
same poses. Both are Gauss–Newton covariances in the pose's own frame over
(x, y, θ), so on the same cost they must agree to the prior's effect.

The cost is not quite the same by default: GTSAM's BetweenFactorPose2 error
is Logmap(Z⁻¹ Xi⁻¹ Xj), g2o's (and slamd's) the (x, y, θ) of Z⁻¹ Xi⁻¹ Xj.
They agree where the error is zero, but their Jacobians differ to first
order in the residual's angle, so the covariances differ (6e-3 at most
on Manhattan). `--cost g2o` (the default) hands GTSAM each edge as a
CustomFactor with g2o's error and its Jacobians in GTSAM's tangent, written
out below; `--cost gtsam` keeps GTSAM's own factors. Per keyframe past the gauge the
table gives ‖Σ_slamd − Σ_gtsam‖_F / ‖Σ_gtsam‖_F (max and median), and each
side's seconds for all keyframes: slamd's `covariance_seconds` (one
marginal per keyframe, read off the factor) with the slowest single one,
and GTSAM's `Marginals` (linearisation, factorisation and one query per
keyframe; with `--cost g2o` the linearisation calls Python per edge).
"""
import argparse, json, os, subprocess, sys, tempfile, time

import numpy as np
from common import BIN, DATA

FILES = ["manhattanolson3500.g2o", "intel_sesync.g2o", "city10000.g2o"]


def read_covariances(path):
    out = {}
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                continue
            v = line.split()
            u = [float(x) for x in v[1:]]
            s = np.zeros((3, 3))
            s[np.triu_indices(3)] = u
            out[int(v[0])] = s + np.triu(s, 1).T
    return out


def g2o_factor(gtsam, between):
    """`between` as a CustomFactor on g2o's error e = (x, y, θ) of
    E = Z⁻¹ D, D = Xi⁻¹ Xj. In GTSAM's tangent (X ← X·Exp(ξ)), to first
    order: ∂e/∂ξj = diag(R_E, 1); ∂e/∂ξi: −R_Zᵀ on ξ_t, −R_Zᵀ J t_D on ξ_θ
    (J the 90° turn) and −1 from θ to θ."""
    i, j = between.keys()
    z = between.measured()
    rz = z.rotation().matrix()

    def error(this, values, jacobians):
        d = values.atPose2(i).between(values.atPose2(j))
        e = z.between(d)
        if jacobians is not None:
            hj = np.eye(3)
            hj[:2, :2] = e.rotation().matrix()
            hi = -np.eye(3)
            hi[:2, :2] = -rz.T
            hi[:2, 2] = -rz.T @ np.array([-d.y(), d.x()])
            jacobians[0] = hi
            jacobians[1] = hj
        return np.array([e.x(), e.y(), e.theta()])

    return gtsam.CustomFactor(between.noiseModel(), [i, j], error)


def gtsam_marginals(g2o, cost):
    import gtsam

    read, values = gtsam.readG2o(g2o, False)
    graph = read
    if cost == "g2o":
        graph = gtsam.NonlinearFactorGraph()
        for f in range(read.size()):
            graph.add(g2o_factor(gtsam, read.at(f)))
    keys = sorted(values.keys())
    graph.add(gtsam.PriorFactorPose2(keys[0], values.atPose2(keys[0]), gtsam.noiseModel.Isotropic.Sigma(3, 1e-6)))
    start = time.perf_counter()
    marginals = gtsam.Marginals(graph, values)
    cov = {k: marginals.marginalCovariance(k) for k in keys}
    return cov, time.perf_counter() - start


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--files", nargs="*", default=FILES)
    ap.add_argument("--cost", choices=["g2o", "gtsam"], default="g2o")
    args = ap.parse_args()
    print("| file | keyframes | max rel. difference | median | slamd s | slamd slowest ms | GTSAM s |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.files:
            out, cov = os.path.join(tmp, "out.g2o"), os.path.join(tmp, "out.cov")
            run = subprocess.run(
                [BIN, "solve", os.path.join(DATA, name), "--polish", "--json", "--out", out, "--covariances", cov],
                check=True, capture_output=True, text=True,
            )
            summary = json.loads(run.stdout)
            ours_s, slowest = summary["covariance_seconds"], summary["covariance_max_seconds"]
            ours = read_covariances(cov)
            theirs, theirs_s = gtsam_marginals(out, args.cost)
            rel = [
                np.linalg.norm(ours[k] - theirs[k]) / np.linalg.norm(theirs[k])
                for k in sorted(ours)[1:]
            ]
            print(f"| {name} | {len(ours)} | {max(rel):.2e} | {np.median(rel):.2e} | {ours_s:.3f} | {1e3 * slowest:.3f} | {theirs_s:.3f} |")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
