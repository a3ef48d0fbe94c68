//! The incremental solve `x = A⁻¹ b` and the marginal form `Vᵀ A⁻¹ V`
//! against dense solves, through appends, updates, downdates and
//! right-hand side changes.

use super::{close, start, to_c, FromParts};
use crate::sparse::dynamic::{DynamicLdlt, IncrementalCholesky, Marginal};
use faer::c64;
use faer::sparse::linalg::SupernodalThreshold;
use nalgebra::DMatrix;
use proptest::prelude::*;

/// One change to the system.
#[derive(Clone, Debug)]
enum Op {
    Append,
    /// Update with a sparse w (positions taken modulo n, weights).
    Update(Vec<(usize, f64, f64)>),
    /// Downdate of the update applied `k` ops back (mod the applied count).
    UndoUpdate(usize),
    Rhs(usize, f64, f64),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        1 => Just(Op::Append),
        4 => prop::collection::vec((0usize..64, -2.0..2.0f64, -2.0..2.0f64), 1..5).prop_map(Op::Update),
        2 => (0usize..64).prop_map(Op::UndoUpdate),
        2 => (0usize..64, -3.0..3.0f64, -3.0..3.0f64).prop_map(|(k, a, b)| Op::Rhs(k, a, b)),
    ]
}

fn run<M: FromParts, V: FromParts + std::ops::Mul<M, Output = V>>(
    n: usize,
    seed: Vec<(usize, usize, f64, f64)>,
    perm_seed: u64,
    ops: Vec<Op>,
) -> Result<(), TestCaseError> {
    let (a, mut dense) = start::<M>(n, &seed);
    // a random permutation
    let mut perm: Vec<usize> = (0..n).collect();
    let mut s = perm_seed;
    for i in (1..n).rev() {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        perm.swap(i, (s >> 33) as usize % (i + 1));
    }
    // both of faer's kinds of fresh factor
    let kind = if perm_seed.is_multiple_of(2) {
        SupernodalThreshold::FORCE_SIMPLICIAL
    } else {
        SupernodalThreshold::FORCE_SUPERNODAL
    };
    let f = DynamicLdlt::<M>::from_matrix_with(&a, &perm, kind)
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    // dense is in the original order; permute it into the factor's order
    let mut dense_p = DMatrix::from_fn(n, n, |i, j| dense[(perm[i], perm[j])]);
    prop_assert!(
        close(&to_c(&f.to_dense()), &dense_p, 1e-12),
        "fresh factor differs"
    );
    dense = dense_p.clone();
    let mut b = vec![V::default(); n];
    let mut chol = IncrementalCholesky::<M, V>::new(f, b.clone());
    let mut applied: Vec<Vec<(usize, M)>> = Vec::new();
    for op in ops {
        let n = chol.len();
        match op {
            Op::Append => {
                chol.append();
                b.push(V::default());
                // a new variable needs weight before it can be solved
                let k = n;
                let w = vec![(k, M::from_real(1.0))];
                chol.rank1(&w, 1.0)
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
                dense = dense
                    .insert_row(n, c64::new(0.0, 0.0))
                    .insert_column(n, c64::new(0.0, 0.0));
                dense[(k, k)] = c64::new(1.0, 0.0);
                applied.push(w);
            }
            Op::Update(entries) => {
                let mut w: Vec<(usize, M)> = Vec::new();
                for (i, re, im) in entries {
                    let i = i % n;
                    if !w.iter().any(|&(j, _)| j == i) {
                        w.push((i, M::from_parts(re, im)));
                    }
                }
                chol.rank1(&w, 1.0)
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
                for &(i, vi) in &w {
                    for &(j, vj) in &w {
                        dense[(i, j)] += vi.to_c64() * vj.to_c64().conj();
                    }
                }
                applied.push(w);
            }
            Op::UndoUpdate(k) if !applied.is_empty() => {
                let w = applied.remove(k % applied.len());
                // only undo what leaves the matrix positive definite
                let mut trial = dense.clone();
                for &(i, vi) in &w {
                    for &(j, vj) in &w {
                        trial[(i, j)] -= vi.to_c64() * vj.to_c64().conj();
                    }
                }
                if trial
                    .clone()
                    .cholesky()
                    .is_some_and(|c| c.l().diagonal().iter().all(|d| d.re > 1e-3))
                {
                    chol.rank1(&w, -1.0)
                        .map_err(|e| TestCaseError::fail(e.to_string()))?;
                    dense = trial;
                }
            }
            Op::UndoUpdate(_) => {}
            Op::Rhs(k, re, im) => {
                let v = V::from_parts(re, im);
                chol.add_rhs(k % n, v);
                b[k % n] += v;
            }
        }
        prop_assert!(
            close(&to_c(&chol.factor().to_dense()), &dense, 1e-9),
            "factor drifted from A"
        );
        chol.solve(0.0);
        let rhs = nalgebra::DVector::from_iterator(b.len(), b.iter().map(|v| v.to_c64()));
        let expected = dense.clone().cholesky().expect("SPD").solve(&rhs);
        let scale = expected.iter().map(|v| v.norm()).fold(1.0, f64::max);
        for (got, want) in chol.x().iter().zip(expected.iter()) {
            prop_assert!(
                (got.to_c64() - want).norm() <= 1e-8 * scale,
                "x {got:?} vs {want}"
            );
        }
        dense_p = dense.clone();
    }
    let _ = dense_p;
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn real_updates_match_dense(n in 1usize..20, seed in prop::collection::vec((0usize..40, 0usize..40, -1.0..1.0f64, -1.0..1.0f64), 0..30), p in any::<u64>(), ops in prop::collection::vec(op(), 1..40)) {
        run::<f64, f64>(n, seed, p, ops)?;
    }

    #[test]
    fn complex_updates_match_dense(n in 1usize..20, seed in prop::collection::vec((0usize..40, 0usize..40, -1.0..1.0f64, -1.0..1.0f64), 0..30), p in any::<u64>(), ops in prop::collection::vec(op(), 1..40)) {
        run::<c64, c64>(n, seed, p, ops)?;
    }

    #[test]
    fn real_matrix_complex_vectors(n in 1usize..20, seed in prop::collection::vec((0usize..40, 0usize..40, -1.0..1.0f64, -1.0..1.0f64), 0..30), p in any::<u64>(), ops in prop::collection::vec(op(), 1..40)) {
        run::<f64, c64>(n, seed, p, ops)?;
    }
}

#[test]
fn appended_block_fills_through_zero_pivots() {
    // Three new variables receive three rank-1 updates, as a new keyframe
    // does from its first edge: zero pivots are expected on the way.
    let (a, _) = start::<f64>(2, &[]);
    let mut chol =
        IncrementalCholesky::<f64, f64>::new(DynamicLdlt::from_matrix(&a, &[0, 1]).unwrap(), vec![0.0; 2]);
    for _ in 0..3 {
        chol.append();
    }
    let rows = [[0.5, 1.0, 2.0, 0.0], [0.0, 0.0, 1.0, 3.0], [1.0, 1.0, 0.0, 1.0]];
    for r in rows {
        let w: Vec<(usize, f64)> = vec![(1, r[0]), (2, r[1]), (3, r[2]), (4, r[3])];
        chol.rank1(&w, 1.0).unwrap();
    }
    chol.add_rhs(4, 1.0);
    chol.solve(0.0);
    let mut dense = DMatrix::<f64>::identity(5, 5);
    dense[(2, 2)] = 0.0;
    dense[(3, 3)] = 0.0;
    dense[(4, 4)] = 0.0;
    for r in rows {
        let v = nalgebra::DVector::from_vec(vec![0.0, r[0], r[1], r[2], r[3]]);
        dense += &v * v.transpose();
    }
    let mut rhs = nalgebra::DVector::zeros(5);
    rhs[4] = 1.0;
    let want = dense.cholesky().unwrap().solve(&rhs);
    for (g, w) in chol.x().iter().zip(want.iter()) {
        assert!((g - w).abs() < 1e-12, "{g} vs {w}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// `Vᵀ A⁻¹ V` read off the paths matches the dense inverse, on a
    /// shuffled ordering and after an update (so the paths are the grown
    /// ones), for vectors over scattered columns.
    #[test]
    fn marginal_form_matches_the_dense_inverse(
        n in 3usize..30,
        seed in prop::collection::vec((0usize..40, 0usize..40, -1.0..1.0f64), 0..40),
        v in prop::collection::vec((0usize..40, 0usize..6, -2.0..2.0f64), 1..15),
        m in 1usize..=6,
        p in any::<u64>(),
    ) {
        let seed: Vec<_> = seed.iter().map(|&(i, j, a)| (i, j, a, 0.0)).collect();
        let (a, mut dense) = start::<f64>(n, &seed);
        let mut perm: Vec<usize> = (0..n).collect();
        perm.sort_by_key(|&i| (i as u64).wrapping_mul(p | 1).rotate_left(17));
        let mut f = DynamicLdlt::<f64>::from_matrix(&a, &perm).unwrap();
        // the factor's columns are in elimination order: column c holds
        // variable perm[c]
        let w = [(0, 0.5), (n - 1, -0.7)];
        f.rank_k_with(&[&w], 1.0, |_, _| {}).unwrap();
        for &(c, wc) in &w {
            for &(d, wd) in &w {
                dense[(perm[c], perm[d])] += c64::new(wc * wd, 0.0);
            }
        }
        // m vectors, as many as a pose's degrees of freedom
        let mut vectors: Vec<Vec<(usize, f64)>> = vec![Vec::new(); m];
        let mut dense_v = DMatrix::<c64>::zeros(n, m);
        for &(i, r, x) in &v {
            let (c, r) = (i % n, r % m);
            if vectors[r].iter().all(|&(k, _)| k != c) {
                vectors[r].push((c, x));
                dense_v[(perm[c], r)] = c64::new(x, 0.0);
            }
        }
        let slices: Vec<&[(usize, f64)]> = vectors.iter().map(|v| &v[..]).collect();
        let got = Marginal::<6>::default().form(&f, &slices).unwrap();
        let want = dense_v.adjoint() * dense.try_inverse().unwrap() * &dense_v;
        for r in 0..m {
            for s in 0..m {
                let scale = want[(r, r)].re.abs().max(want[(s, s)].re.abs()).max(1.0);
                prop_assert!((got[(r, s)] - want[(r, s)].re).abs() <= 1e-9 * scale, "{r},{s}: {} vs {}", got[(r, s)], want[(r, s)].re);
            }
        }
    }
}
