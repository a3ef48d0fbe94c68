#!/usr/bin/env python3
"""The scale of a file's information, read off short cycles of loop-closure
pairs, and what wrong loop closures do to it.

    python3 benches/cycle_scale.py [manhattan intel ringcity city]

For each loop closure a = (i_a, j_a) the nearest other one b (least
|i_a − i_b| + |j_a − j_b|, both within 4 keyframes) closes a short cycle
with the odometry between their ends: PCM's test (benches/pcm.py), whose
χ² at scale s is s · χ²₃ when both are right. The scale estimate is the
median of those χ² over χ²₃'s median (and the first quartile over its
first quartile), on the outlier-free file and with 4000 wrong loop
closures of three kinds (`../shared/tools/add_outliers.py`, seed 1),
beside the variance factor χ²/r of the clean file's optimum (the oracle).
"""
import os, subprocess, sys, tempfile

import numpy as np

from common import DATA, slamd
from pcm import Chain, adjoint, chain_of, inverse, loop_closures, read_g2o, sandwich

FILES = {"manhattan": "manhattanolson3500_g2oversion.g2o", "intel": "intel_sesync.g2o",
         "ringcity": "ringcity.g2o", "city": "city10000.g2o"}
TOOL = os.path.join(DATA, "..", "tools", "add_outliers.py")
CHI2_3_MEDIAN, CHI2_3_Q25 = 2.3660, 1.2125


def estimate(path, reach=4):
    """(loop closures, paired ones, median scale, first-quartile scale)."""
    vertices, edges = read_g2o(path)
    odometry, _, I, J, Z, C = loop_closures(edges)
    back = I > J  # older first: (T Exp ξ)⁻¹ = T⁻¹ Exp(−Ad_T ξ)
    I[back], J[back] = J[back], I[back]
    C[back], Z[back] = sandwich(adjoint(Z[back]), C[back]), inverse(Z[back])
    chain = Chain(max(vertices) + 1, odometry, 1.0)
    d2 = []
    for a in range(len(I)):
        near = np.flatnonzero((np.abs(I - I[a]) <= reach) & (np.abs(J - J[a]) <= reach))
        near = near[near != a]
        if len(near) == 0:
            continue
        b = near[np.argmin(np.abs(I[near] - I[a]) + np.abs(J[near] - J[a]))]
        s = slice(a, a + 1)
        back = (inverse(Z[b:b + 1]), sandwich(adjoint(Z[b:b + 1]), C[b:b + 1]))
        T, S = chain_of([(Z[s], C[s]), chain.between(J[s], J[b:b + 1]), back, chain.between(I[b:b + 1], I[s])])
        d2.append(float(np.einsum("ni,nij,nj->n", T, np.linalg.inv(S), T)[0]))
    return len(I), len(d2), np.median(d2) / CHI2_3_MEDIAN, np.percentile(d2, 25) / CHI2_3_Q25


def main():
    tmp = tempfile.mkdtemp(prefix="slamd-cycle-scale-")
    print("`python3 benches/cycle_scale.py " + " ".join(sys.argv[1:]) + "`")
    print()
    print("| file | loop closures | paired | scale (median) | scale (first quartile) | oracle χ²/r |")
    print("|---|---|---|---|---|---|")
    for name in sys.argv[1:] or FILES:
        clean = os.path.join(DATA, FILES[name])
        r = slamd("solve", clean, "--polish", "--json")
        oracle = r["chi2"] / (3 * r["edges"] - 3 * (r["nodes"] - 1))
        m, paired, med, q25 = estimate(clean)
        print(f"| {name} | {m} | {paired} | {med:.4f} | {q25:.4f} | {oracle:.4f} |")
        for kind in ["random", "local", "local-grouped"]:
            spoiled = os.path.join(tmp, f"{name}-{kind}.g2o")
            subprocess.run([sys.executable, TOOL, "-i", clean, "-o", spoiled, "--kind", kind,
                            "--count", "4000", "--seed", "1"], check=True, capture_output=True)
            m, paired, med, q25 = estimate(spoiled)
            print(f"| + 4000 {kind} | {m} | {paired} | {med:.4f} | {q25:.4f} | |")


if __name__ == "__main__":
    main()
