#!/usr/bin/env python3
"""Pairwise consistency maximisation (PCM) on Vertigo's outliers, beside slamd's filter.

    cargo build --release --bin slamd
    python3 benches/pcm.py [--datasets intel manhattan ringcity city]
                           [--kinds random local random-grouped local-grouped]
                           [--counts 1000 4000] [--seeds 1 2] [--scale S] [--clean]

A reference implementation of PCM (Mangelson, Dominic, Eustice and
Vasudevan, ICRA 2018; the loop-closure front of Kimera-RPGO) in SE(2),
measured on the files `benches/outliers.py` spoils, in one run with
`slamd replay --embedded` on the same file:

- Two loop closures a = (i_a, j_a, Z_a) and b = (i_b, j_b, Z_b) are
  consistent when the cycle i_a →Z_a→ j_a →odometry→ j_b →Z_b⁻¹→ i_b
  →odometry→ i_a closes: its error e (x, y, θ of the composed pose) has
  eᵀ Σ⁻¹ e < χ²₃(0.99) = 11.34, Σ the first-order covariance of the four
  pieces (right perturbations, odometry covariances summed along the
  chain through prefix sums of Ad(D_k) Σ_k Ad(D_k)ᵀ, D the dead reckoning).
- The kept loop closures are a maximum clique of the consistency graph,
  found greedily from the `--starts` vertices of highest degree (each step
  adds the candidate with the most neighbours among the remaining
  candidates).
- Every covariance is multiplied by `--scale`. By default that is the
  variance factor χ²/r of the clean file's least-squares optimum (r the
  redundancy, 3·edges − 3·(keyframes − 1)): the datasets' information
  matrices are pessimistic, so at scale 1 a cycle a few metres off is
  still "consistent". This is an oracle calibration; an online filter
  would have to estimate it.

Caught means left out of the clique (PCM) or a final switch below 0.5
(slamd). --clean runs the outlier-free files instead, where every loop
closure left out is a true one. The spoiled files go to a temporary
directory; ../shared/tools/add_outliers.py makes them.
"""
import argparse, json, os, subprocess, sys, tempfile, time

import numpy as np

from outliers import DATASETS, TOOL  # noqa: E402
from common import BIN, DATA, slamd

CHI2_3_99 = 11.3449


def read_g2o(path):
    """Vertices {id: (x, y, θ)} and edges [(i, j, z, Ω)] of a 2-D g2o file."""
    vertices, edges = {}, []
    for line in open(path):
        t = line.split()
        if t and t[0] == "VERTEX_SE2":
            vertices[int(t[1])] = tuple(map(float, t[2:5]))
        elif t and t[0] == "EDGE_SE2":
            I = list(map(float, t[6:12]))
            omega = np.array([[I[0], I[1], I[2]], [I[1], I[3], I[4]], [I[2], I[4], I[5]]])
            edges.append((int(t[1]), int(t[2]), np.array(list(map(float, t[3:6]))), omega))
    return vertices, edges


def loop_closures(edges):
    """Split a graph's edges (`read_g2o`): the odometry by its older keyframe, `(z, Ω)`, and the
    loop closures as arrays: file edge index E, ends I and J, measurement Z and covariance C = Ω⁻¹."""
    odometry, loops = {}, []
    for e, (i, j, z, omega) in enumerate(edges):
        if j == i + 1 and i not in odometry:
            odometry[i] = (z, omega)
        else:
            loops.append((e, i, j, z, np.linalg.inv(omega)))
    E, I, J = (np.array([l[k] for l in loops], dtype=int) for k in range(3))
    Z, C = np.array([l[3] for l in loops]), np.array([l[4] for l in loops])
    return odometry, E, I, J, Z, C


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def compose(a, b):
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1],
                     a[..., 1] + s * b[..., 0] + c * b[..., 1], wrap(a[..., 2] + b[..., 2])], -1)


def inverse(a):
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([-(c * a[..., 0] + s * a[..., 1]), s * a[..., 0] - c * a[..., 1], -a[..., 2]], -1)


def adjoint(a):
    """Ad of SE(2) in (x, y, θ) order: [[R, (y, −x)ᵀ], [0, 1]]; T Exp(ξ) = Exp(Ad_T ξ) T."""
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    A = np.zeros(a.shape[:-1] + (3, 3))
    A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1] = c, -s, s, c
    A[..., 0, 2], A[..., 1, 2], A[..., 2, 2] = a[..., 1], -a[..., 0], 1.0
    return A


def sandwich(A, S):
    return A @ S @ np.swapaxes(A, -1, -2)


class Chain:
    """Dead reckoning D_k and prefix sums P_m = Σ_{k<m} Ad(D_{k+1}) Σ_k Ad(D_{k+1})ᵀ of the odometry,
    Σ_k its covariance × `scale`, or the part of it `part` keeps."""

    def __init__(self, n, odometry, scale, part=None):
        self.D = np.zeros((n, 3))
        self.P = np.zeros((n, 3, 3))
        for k in range(n - 1):
            z, omega = odometry[k]
            cov = np.linalg.inv(omega) * scale
            self.D[k + 1] = compose(self.D[k], z)
            self.P[k + 1] = self.P[k] + sandwich(adjoint(self.D[k + 1]), part(cov) if part else cov)

    def between(self, a, c):
        """The odometry from keyframes a to c (index arrays): pose and covariance in c's frame."""
        T = compose(inverse(self.D[a]), self.D[c])
        lo, hi = np.minimum(a, c), np.maximum(a, c)
        C = sandwich(adjoint(inverse(self.D[hi])), self.P[hi] - self.P[lo])
        back = a > c  # (T Exp ξ)⁻¹ = T⁻¹ Exp(−Ad_T ξ)
        if np.any(back):
            C[back] = sandwich(adjoint(inverse(T[back])), C[back])
        return T, C


def chain_of(parts):
    """Compose [(T, Σ)] with right perturbations: Σ ← Ad(T₂⁻¹) Σ Ad(T₂⁻¹)ᵀ + Σ₂."""
    T, C = parts[0]
    for T2, C2 in parts[1:]:
        C = sandwich(adjoint(inverse(T2)), C) + C2
        T = compose(T, T2)
    return T, C


def consistency(chain, I, J, Z, C):
    """The boolean consistency matrix of loop closures (I, J, Z, C)."""
    m = len(I)
    adj = np.zeros((m, m), bool)
    for b in range(1, m):
        a = np.arange(b)
        zb = (np.broadcast_to(inverse(Z[b]), (b, 3)), np.broadcast_to(sandwich(adjoint(Z[b]), C[b]), (b, 3, 3)))
        T, S = chain_of([(Z[a], C[a]), chain.between(J[a], np.full(b, J[b])), zb,
                         chain.between(np.full(b, I[b]), I[a])])
        d2 = np.einsum("ni,nij,nj->n", T, np.linalg.inv(S), T)
        adj[b, a] = adj[a, b] = d2 < CHI2_3_99
    return adj


def max_clique(adj, starts):
    """A large clique, greedily from the `starts` vertices of highest degree."""
    degree = adj.sum(1)
    best = []
    for v in np.argsort(-degree)[:starts]:
        if degree[v] < len(best):
            continue
        clique, cand = [v], adj[v].copy()
        inner = adj[:, cand].sum(1).astype(np.int64)
        while cand.any():
            idx = np.flatnonzero(cand)
            u = idx[np.argmax(inner[idx])]
            clique.append(u)
            drop = cand & ~adj[u]
            drop[u] = True
            cand &= ~drop
            inner -= adj[:, drop].sum(1)
        if len(clique) > len(best):
            best = clique
    return best


def pcm(path, scale, starts):
    """Edge indices (among the file's edges) PCM leaves out, and seconds."""
    vertices, edges = read_g2o(path)
    odometry, E, I, J, Z, C = loop_closures(edges)
    t = time.perf_counter()
    chain = Chain(max(vertices) + 1, odometry, scale)
    kept = {int(E[q]) for q in max_clique(consistency(chain, I, J, Z, C * scale), starts)}
    return {int(e) for e in E} - kept, len(E), time.perf_counter() - t


def variance_factor(binary, clean):
    r = slamd("solve", clean, "--polish", "--json", binary=binary)
    return r["chi2"] / (3 * r["edges"] - 3 * (r["nodes"] - 1))


def pr(left_out, injected):
    caught = left_out & injected
    return len(caught) / max(1, len(left_out)), len(caught) / max(1, len(injected))


def without(path, left_out, out):
    """Writes `path` without the edges `left_out` (indices among its edges) to `out`;
    returns the original index of each edge kept."""
    kept, e = [], 0
    with open(out, "w") as f:
        for line in open(path):
            if line.startswith("EDGE_SE2"):
                e += 1
                if e - 1 in left_out:
                    continue
                kept.append(e - 1)
            f.write(line)
    return kept


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slamd", default=BIN)
    ap.add_argument("--datasets", nargs="+", default=["intel", "manhattan", "ringcity"])
    ap.add_argument("--kinds", nargs="+", default=["random", "local", "random-grouped", "local-grouped"])
    ap.add_argument("--counts", nargs="+", type=int, default=[1000, 4000])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1])
    ap.add_argument("--scale", type=float, default=None, help="covariance multiplier (default: the variance factor)")
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--clean", action="store_true", help="the outlier-free files only")
    ap.add_argument("--then-slamd", action="store_true",
                    help="also replay the file without PCM's rejections through slamd's filter")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="slamd-pcm-")
    then = " PCM then slamd P / R | PCM then slamd true off |" if args.then_slamd else ""
    print("| dataset | outliers | seed | slamd P / R | slamd true off | slamd (s) | PCM scale | PCM P / R | "
          "PCM true left out | PCM (s) |" + then)
    print("|---|---|---|---|---|---|---|---|---|---|" + "---|---|" * args.then_slamd)
    for name in args.datasets:
        clean = os.path.join(DATA, DATASETS[name][0])
        scale = args.scale if args.scale is not None else variance_factor(args.slamd, clean)
        runs = [("none", "–", clean, set())] if args.clean else []
        for seed in ([] if args.clean else args.seeds):
            for kind in args.kinds:
                for count in args.counts:
                    spoiled = os.path.join(tmp, f"{name}-{kind}-{count}-{seed}.g2o")
                    subprocess.run([sys.executable, TOOL, "-i", clean, "-o", spoiled, "--kind", kind, "--count",
                                    str(count), "--seed", str(seed)], check=True, capture_output=True)
                    side = json.load(open(spoiled + ".outliers.json"))
                    runs.append((f"{count} {kind}", seed, spoiled, {o["edge_index"] for o in side["outliers"]}))
        for label, seed, path, injected in runs:
            r = slamd("replay", path, "--embedded", "--json", binary=args.slamd)
            off = set(r["rejected_edges"])
            sp, sr = pr(off, injected)
            left_out, loops, secs = pcm(path, scale, args.starts)
            pp, prr = pr(left_out, injected)
            row = (f"| {name} | {label} | {seed} | {sp:.3f} / {sr:.3f} | {len(off - injected)} | {r['total_s']:.2f} | "
                   f"{scale:.3f} | {pp:.3f} / {prr:.3f} | {len(left_out - injected)} of {loops - len(injected)} | "
                   f"{secs:.1f} |")
            if args.then_slamd:
                rest = path + ".pcm.g2o"
                index = without(path, left_out, rest)
                r2 = slamd("replay", rest, "--embedded", "--json", binary=args.slamd)
                both = left_out | {index[e] for e in r2["rejected_edges"]}
                bp, br = pr(both, injected)
                row += f" {bp:.3f} / {br:.3f} | {len(both - injected)} |"
            print(row, flush=True)


if __name__ == "__main__":
    sys.exit(main())
