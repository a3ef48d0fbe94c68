#!/usr/bin/env python3
"""g2o's cost of a pose graph's edges as written, scored outside slamd.

    pip install numpy scipy
    python3 benches/as_written.py GRAPH POSES [--lm]

GRAPH: a g2o file, 2-D (`EDGE_SE2`) or 3-D (`EDGE_SE3:QUAT`). POSES: a g2o
file's `VERTEX_*` lines (what `slamd solve --out X.g2o` writes) or a table
`id x y theta` / `id x y z qx qy qz qw`. Every edge `(i, j, Z, Ω)` counts as
written, whichever id is larger:

    2-D  e = t2v(Z⁻¹ X_i⁻¹ X_j)                  (x, y, wrapped θ)
    3-D  e = [Δt, Δq_xyz] of Δ = Z⁻¹ X_i⁻¹ X_j    (quaternion with w ≥ 0)

and χ² = Σ eᵀ Ω e, in numpy, sharing no code with slamd. Edges whose
information is not positive definite are skipped and counted (what
`slamd solve --skip-invalid` does).

--lm then runs a Levenberg–Marquardt of this script's own (numeric
Jacobians, scipy's sparse solver) on the same cost from POSES and reports
where it stops and the largest entry of the gradient it started from: a
map at its optimum comes back at the same χ², one short of it lower.
(GTSAM is no referee here: its Pose2 error is the Lie logarithm, not g2o's
t2v, and its Pose3 error the rotation vector, not the quaternion vector.)
"""
import argparse, math, sys

import numpy as np

from common import positive_definite, upper


def quat_matrix(qx, qy, qz, qw):
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_quat(r):
    """The unit quaternion (x, y, z, w) of a rotation matrix, w ≥ 0."""
    t = np.trace(r)
    if t > 0:
        s = 2 * math.sqrt(1 + t)
        q = np.array([(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4])
    else:
        k = int(np.argmax(np.diag(r)))
        i, j = (k + 1) % 3, (k + 2) % 3
        s = 2 * math.sqrt(1 + r[k, k] - r[i, i] - r[j, j])
        q = np.zeros(4)
        q[k], q[i], q[j], q[3] = s / 4, (r[i, k] + r[k, i]) / s, (r[j, k] + r[k, j]) / s, (r[j, i] - r[i, j]) / s
    return q if q[3] >= 0 else -q


def homogeneous2(x, y, th):
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, x], [s, c, y], [0, 0, 1.0]])


def homogeneous3(x, y, z, qx, qy, qz, qw):
    m = np.eye(4)
    m[:3, :3] = quat_matrix(qx, qy, qz, qw)
    m[:3, 3] = (x, y, z)
    return m


def read_graph(path):
    """(dimension, edges [(i, j, Z⁻¹ as a homogeneous matrix, Ω)], skipped):
    Z inverted once here, since every error evaluation needs Z⁻¹."""
    edges, skipped, dim = [], 0, None
    for line in open(path):
        t = line.split()
        if not t:
            continue
        if t[0] == "EDGE_SE2":
            dim = 2
            z, omega = homogeneous2(*map(float, t[3:6])), upper(list(map(float, t[6:12])), 3)
        elif t[0] == "EDGE_SE3:QUAT":
            dim = 3
            z, omega = homogeneous3(*map(float, t[3:10])), upper(list(map(float, t[10:31])), 6)
        else:
            continue
        if not positive_definite(omega):
            skipped += 1
            continue
        edges.append((int(t[1]), int(t[2]), np.linalg.inv(z), omega))
    if dim is None:
        sys.exit(f"{path}: no EDGE_SE2 or EDGE_SE3:QUAT lines")
    return dim, edges, skipped


def read_poses(path, dim):
    poses = {}
    for line in open(path):
        t = line.split()
        if not t or t[0].startswith("#") or t[0].startswith("EDGE") or t[0] == "FIX":
            continue
        if t[0].startswith("VERTEX"):
            t = t[1:]
        values = list(map(float, t[1:]))
        poses[int(t[0])] = homogeneous2(*values[:3]) if dim == 2 else homogeneous3(*values[:7])
    return poses


def error(dim, z_inv, xi, xj):
    """g2o's error of an edge whose measurement's inverse is `z_inv`."""
    d = z_inv @ np.linalg.inv(xi) @ xj
    if dim == 2:
        th = math.atan2(d[1, 0], d[0, 0])
        return np.array([d[0, 2], d[1, 2], th])
    q = matrix_quat(d[:3, :3])
    return np.array([d[0, 3], d[1, 3], d[2, 3], q[0], q[1], q[2]])


def chi2(dim, edges, poses):
    total = 0.0
    for i, j, z_inv, omega in edges:
        e = error(dim, z_inv, poses[i], poses[j])
        total += float(e @ omega @ e)
    return total


def moved(dim, m, c, h):
    """`m` moved by `h` along coordinate `c`: x, y, θ added in 2-D; in 3-D
    the translation added, the rotation turned by `h` about axis `c − 3`."""
    out = m.copy()
    if dim == 2:
        x, y, th = m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])
        v = [x, y, th]
        v[c] += h
        return homogeneous2(*v)
    if c < 3:
        out[c, 3] += h
        return out
    a = np.zeros(3)
    a[c - 3] = h
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    turn = np.eye(3) + math.sin(h) / h * k + (1 - math.cos(h)) / (h * h) * (k @ k) if h else np.eye(3)
    out[:3, :3] = turn @ m[:3, :3]
    return out


def levenberg_marquardt(dim, edges, poses, iterations=30):
    """Minimises the as-written χ² from `poses` (the smallest id fixed) with
    numeric Jacobians: an optimiser that shares nothing with slamd's. Returns
    (poses, χ² at the end, largest gradient entry at the start)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    dof = 3 if dim == 2 else 6
    ids = sorted(poses)
    col = {k: n * dof for n, k in enumerate(ids[1:])}
    size = dof * (len(ids) - 1)
    h = 1e-6
    poses = dict(poses)
    cost = chi2(dim, edges, poses)
    first_gradient, lam = None, 1e-6
    for _ in range(iterations):
        rows, cols, vals, g = [], [], [], np.zeros(size)
        for i, j, z_inv, omega in edges:
            e = error(dim, z_inv, poses[i], poses[j])
            jac = np.zeros((dof, 2 * dof))
            for side, k in enumerate((i, j)):
                for c in range(dof):
                    def at(step):
                        ends = [poses[i], poses[j]]
                        ends[side] = moved(dim, poses[k], c, step)
                        return error(dim, z_inv, *ends)
                    d = at(h) - at(-h)
                    if dim == 2:
                        d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
                    jac[:, side * dof + c] = d / (2 * h)
            hess, grad = jac.T @ omega @ jac, jac.T @ omega @ e
            for a, ka in enumerate((i, j)):
                if ka not in col:
                    continue
                g[col[ka]:col[ka] + dof] += grad[a * dof:(a + 1) * dof]
                for b, kb in enumerate((i, j)):
                    if kb not in col:
                        continue
                    block = hess[a * dof:(a + 1) * dof, b * dof:(b + 1) * dof]
                    r, c = np.meshgrid(range(col[ka], col[ka] + dof), range(col[kb], col[kb] + dof), indexing="ij")
                    rows.extend(r.ravel()), cols.extend(c.ravel()), vals.extend(block.ravel())
        if first_gradient is None:
            first_gradient = float(np.abs(2 * g).max())
        hess = sp.csc_matrix((vals, (rows, cols)), shape=(size, size))
        while True:
            damped = hess + lam * sp.diags(hess.diagonal())
            step = spla.spsolve(damped.tocsc(), -g)
            trial = {}
            for k, m in poses.items():
                if k not in col:
                    trial[k] = m
                    continue
                for c in range(dof):
                    m = moved(dim, m, c, step[col[k] + c])
                trial[k] = m
            new = chi2(dim, edges, trial)
            if new < cost:
                poses, lam = trial, max(lam / 10, 1e-12)
                break
            lam *= 10
            if lam > 1e8:
                return poses, cost, first_gradient
        done = cost - new < 1e-12 * cost
        cost = new
        if done:
            break
    return poses, cost, first_gradient


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("graph")
    ap.add_argument("poses")
    ap.add_argument("--lm", action="store_true", help="minimise from POSES with this script's own LM and report where it stops")
    args = ap.parse_args()
    dim, edges, skipped = read_graph(args.graph)
    poses = read_poses(args.poses, dim)
    newer_first = sum(1 for i, j, _, _ in edges if i > j)
    print(f"{args.graph}: {len(edges)} edges ({newer_first} newer-id-first, {skipped} skipped: information not positive definite)")
    print(f"chi2 as written: {chi2(dim, edges, poses):.4f}")
    if args.lm:
        _, end, gradient = levenberg_marquardt(dim, edges, poses)
        print(f"largest gradient entry at POSES: {gradient:.3e}")
        print(f"chi2 after this script's LM from POSES: {end:.4f}")


if __name__ == "__main__":
    main()
