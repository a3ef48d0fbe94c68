#!/usr/bin/env python3
"""Variance components: the filter at information calibrated per group.

    cargo build --release --bin slamd
    python3 benches/variance_components.py intel random:4000 local:4000 local-grouped:1000

Estimates a variance factor for each of four groups (odometry and loop
closures, translation and rotation) at the outlier-free file's optimum by
Förstner's iteration: σ²_c ← σ²_c · vᵀWv_c / r_c, where vᵀWv_c is the
group's part of the weighted residuals and r_c its redundancy, the sum of
1 − (W J H⁻¹ Jᵀ)_kk over its components (exact: a dense H⁻¹, so 2-D files
up to a few thousand keyframes). The factors are an oracle: they come from
the outlier-free optimum, which a filter online would have to estimate.

Every edge's information is then scaled by its group's factors
(D Ω D, D = diag(σ_t⁻¹, σ_t⁻¹, σ_r⁻¹)); an injected loop closure takes the
loop-closure group's. The outlier-free file and each spoiled one
(`../shared/tools/add_outliers.py`, seed 1; rows as KIND:COUNT) are
replayed (`slamd replay --embedded`, filter defaults) as written and
calibrated, and scored by precision and recall of the injected edges.

It also prints how each true loop closure agrees with the odometry between
its ends (`chain_chi2`): the test PCM and an innovation gate rest on, as
written and at the calibrated scale.
"""
import json, math, os, subprocess, sys, tempfile

import numpy as np

from common import BIN, DATA, upper

TOOL = os.path.join(DATA, "..", "tools", "add_outliers.py")
FILES = {"intel": "intel_sesync.g2o", "ringcity": "ringcity.g2o", "manhattan": "manhattanolson3500_g2oversion.g2o"}


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def edges(path):
    """(line number, i, j, z, Ω) of every EDGE_SE2 line."""
    for n, line in enumerate(open(path).read().splitlines()):
        t = line.split()
        if t and t[0] == "EDGE_SE2":
            yield n, int(t[1]), int(t[2]), list(map(float, t[3:6])), upper(list(map(float, t[6:12])), 3)


def group(i, j):
    return 0 if abs(j - i) == 1 else 1


def factors(clean, iterations=8):
    """The four variance factors [[odometry t, r], [loop closure t, r]]."""
    opt = tempfile.mktemp(suffix=".txt")
    subprocess.run([BIN, "solve", clean, "--polish", "--out", opt], check=True, capture_output=True)
    x = {int(k): np.array(list(map(float, v))) for k, *v in (l.split() for l in open(opt))}
    col = {k: 3 * n for n, k in enumerate(sorted(x))}
    rows = []
    for _, i, j, z, info in edges(clean):
        c, s = math.cos(x[i][2]), math.sin(x[i][2])
        dx, dy = x[j][0] - x[i][0], x[j][1] - x[i][1]
        rel = np.array([c * dx + s * dy, -s * dx + c * dy, wrap(x[j][2] - x[i][2])])
        cz, sz = math.cos(z[2]), math.sin(z[2])
        rz = np.array([[cz, sz, 0], [-sz, cz, 0], [0, 0, 1]])
        r = rz @ (rel - np.array([z[0], z[1], 0]))
        r[2] = wrap(rel[2] - z[2])
        ji = rz @ np.array([[-c, -s, -s * dx + c * dy], [s, -c, -c * dx - s * dy], [0, 0, -1]])
        jj = rz @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        rows.append((col[i], col[j], r, np.hstack([ji, jj]), info, group(i, j)))
    scale = np.ones((2, 2))
    for _ in range(iterations):
        w = lambda g, info: scaled(info, scale[g])
        h = np.zeros((3 * len(x), 3 * len(x)))
        for a, b, r, jac, info, g in rows:
            idx = list(range(a, a + 3)) + list(range(b, b + 3))
            h[np.ix_(idx, idx)] += jac.T @ w(g, info) @ jac
        h[:3, :3] += 1e8 * np.eye(3)
        hinv = np.linalg.inv(h)
        v, red = np.zeros((2, 2)), np.zeros((2, 2))
        for a, b, r, jac, info, g in rows:
            idx = list(range(a, a + 3)) + list(range(b, b + 3))
            m = w(g, info) @ jac @ hinv[np.ix_(idx, idx)] @ jac.T
            wr = w(g, info) @ r
            v[g] += [r[0] * wr[0] + r[1] * wr[1], r[2] * wr[2]]
            red[g] += [2 - m[0, 0] - m[1, 1], 1 - m[2, 2]]
        scale *= v / red
    return scale


def compose(a, b):
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])])


def inverse(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]])


def adjoint(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([[c, -s, a[1]], [s, c, -a[0]], [0, 0, 1]])


def chain_chi2(clean, scale):
    """Each loop closure's χ² against the odometry between its ends, the
    chain's covariance propagated to first order: χ²₃-distributed for a
    true loop closure when the covariances are right."""
    odometry, closures = {}, []
    for _, i, j, z, info in edges(clean):
        if group(i, j) == 0:
            odometry[min(i, j)] = (i, z, info)
        else:
            closures.append((i, j, z, info))
    out = []
    for i, j, z, info in closures:
        a, b = min(i, j), max(i, j)
        t, p = np.zeros(3), np.zeros((3, 3))
        for k in range(a, b):
            first, step, oinfo = odometry[k]
            ad = adjoint(t)
            p += ad @ np.linalg.inv(scaled(oinfo, scale[0])) @ ad.T
            t = compose(t, np.array(step) if first == k else inverse(np.array(step)))
        zab = np.array(z) if i == a else inverse(np.array(z))
        d = compose(inverse(zab), t)
        ad = adjoint(inverse(zab))
        s = ad @ p @ ad.T + np.linalg.inv(scaled(info, scale[1]))
        out.append(float(d @ np.linalg.solve(s, d)))
    return np.array(out)


def scaled(info, f):
    d = np.diag([f[0] ** -0.5, f[0] ** -0.5, f[1] ** -0.5])
    return d @ info @ d


def calibrate(src, dst, scale):
    out = open(src).read().splitlines()
    for n, i, j, z, info in edges(src):
        m = scaled(info, scale[group(i, j)])
        t = out[n].split()
        out[n] = " ".join(t[:6] + [repr(float(m[r, c])) for r in range(3) for c in range(r, 3)])
    open(dst, "w").write("\n".join(out) + "\n")


def replay(path):
    r = subprocess.run([BIN, "replay", path, "--embedded", "--json"], check=True, capture_output=True, text=True)
    return json.loads(r.stdout)


def main():
    name, rows = sys.argv[1], sys.argv[2:]
    clean = os.path.join(DATA, FILES[name])
    scale = factors(clean)
    print(f"{name}: variance factors odometry t {scale[0, 0]:.4g} r {scale[0, 1]:.4g}, "
          f"loop closures t {scale[1, 0]:.4g} r {scale[1, 1]:.4g}")
    for label, sc in (("as written", np.ones((2, 2))), ("calibrated", scale)):
        c = chain_chi2(clean, sc)
        print(f"true loop closures against the odometry, {label}: χ² median {np.median(c):.2f} "
              f"(χ²₃: 2.37), beyond 16.27 {np.mean(c > 16.27):.1%}")
    print("| outliers | as written P / R | (s) | calibrated P / R | (s) |\n|---|---|---|---|---|")
    tmp = tempfile.mkdtemp(prefix="slamd-vce-")
    for row in ["clean:0"] + rows:
        kind, count = row.split(":")
        spoiled, injected = clean, set()
        if kind != "clean":
            spoiled = os.path.join(tmp, f"{kind}-{count}.g2o")
            subprocess.run([sys.executable, TOOL, "-i", clean, "-o", spoiled, "--kind", kind, "--count", count,
                            "--seed", "1"], check=True, capture_output=True)
            injected = {o["edge_index"] for o in json.load(open(spoiled + ".outliers.json"))["outliers"]}
        calibrated = os.path.join(tmp, f"{kind}-{count}.calibrated.g2o")
        calibrate(spoiled, calibrated, scale)
        cells = []
        for path in (spoiled, calibrated):
            r = replay(path)
            off = set(r["rejected_edges"])
            caught = len(injected & off)
            pr = (f"{caught / max(1, len(off)):.3f} / {caught / len(injected):.3f}" if injected
                  else f"{len(off)} true off")
            cells += [pr, f"{r['total_s']:.2f}"]
        print(f"| {'none' if kind == 'clean' else f'{count} {kind}'} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
