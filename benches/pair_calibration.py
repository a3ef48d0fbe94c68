#!/usr/bin/env python3
"""Can a fitted scale make PCM's pairwise test hold? Variance components
of the short and long cycles two true loop closures close.

    python3 benches/pair_calibration.py [FILE ...]   (default: clean 2-D files)

Every loop closure of an outlier-free file is true, so PCM's test
(benches/pcm.py) should pass 99% of pairs at χ²₃'s 99% quantile once the
covariances are right. For 20,000 random pairs of loop closures the cycle's
first-order covariance is split into four components, the loop closures'
and the odometry's translation and rotation parts (S = Σ θ_c S_c, each S_c
propagated along the cycle alone), and θ is fitted by maximum likelihood
(the fixed point θ_c ← θ_c · Σ uᵀ S_c u / Σ tr(S⁻¹ S_c), u = S⁻¹ e). Printed:
the share of pairs within the 99% bound and the median χ² over χ²₃'s, as
written (θ = 1) and fitted, and for the pairs with the shorter and the
longer half of odometry between their ends.
"""
import os, sys

import numpy as np

from common import DATA
from pcm import Chain, adjoint, chain_of, inverse, loop_closures, read_g2o, sandwich

CHI2_3_99, CHI2_3_MEDIAN = 11.3449, 2.3660
FILES = ["manhattanolson3500_g2oversion.g2o", "intel_sesync.g2o", "ringcity.g2o", "input_m3500b_g2o.g2o",
         "input_intel_g2o.g2o", "mit_killian.g2o"]
TRANSLATION, ROTATION = np.diag([1.0, 1.0, 0.0]), np.diag([0.0, 0.0, 1.0])


def cycles(path, pairs=20000, seed=0):
    """The cycle errors e, their covariance components S_c, and the odometry between their ends."""
    vertices, edges = read_g2o(path)
    odometry, _, I, J, Z, C = loop_closures(edges)
    rng = np.random.default_rng(seed)
    A, B = rng.integers(0, len(I), pairs), rng.integers(0, len(I), pairs)
    A, B = A[A != B], B[A != B]
    none = lambda c: np.zeros_like(c)
    part = lambda m: (lambda c: m @ c @ m)
    components = [(part(TRANSLATION), none), (part(ROTATION), none), (none, part(TRANSLATION)),
                  (none, part(ROTATION))]
    S = []
    for of_loop, of_odometry in components:
        chain = Chain(max(vertices) + 1, odometry, 1.0, of_odometry)
        Cp = np.array([of_loop(c) for c in C])
        back = (inverse(Z[B]), sandwich(adjoint(Z[B]), Cp[B]))
        e, s = chain_of([(Z[A], Cp[A]), chain.between(J[A], J[B]), back, chain.between(I[B], I[A])])
        S.append(s)
    return e, np.array(S), np.abs(J[A] - J[B]) + np.abs(I[A] - I[B])


def fit(e, S, iterations=200):
    theta = np.ones(len(S))
    for _ in range(iterations):
        Si = np.linalg.inv(np.einsum("c,cnij->nij", theta, S) + 1e-15 * np.eye(3))
        u = np.einsum("nij,nj->ni", Si, e)
        theta *= np.einsum("ni,cnij,nj->c", u, S, u) / np.einsum("nij,cnji->c", Si, S)
    return theta


def main():
    paths = sys.argv[1:] or [os.path.join(DATA, f) for f in FILES]
    print("`python3 benches/pair_calibration.py " + " ".join(sys.argv[1:]) + "`")
    print()
    print("| file | θ (loop t, loop r, odometry t, odometry r) | within 99% | shorter half | longer half | median / χ²₃'s |")
    print("|---|---|---|---|---|---|")
    for path in paths:
        e, S, odometry = cycles(path)
        short = odometry < np.median(odometry)
        for theta in (np.ones(4), fit(e, S)):
            d2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(np.einsum("c,cnij->nij", theta, S)), e)
            within = d2 < CHI2_3_99
            label = "as written" if (theta == 1).all() else " ".join(f"{t:.3g}" for t in theta)
            print(f"| {os.path.basename(path)} | {label} | {within.mean():.3f} | {within[short].mean():.3f} | "
                  f"{within[~short].mean():.3f} | {np.median(d2) / CHI2_3_MEDIAN:.3f} |", flush=True)


if __name__ == "__main__":
    main()
