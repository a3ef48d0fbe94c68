//! Property tests: every sequence of appends, updates and downdates keeps
//! `L D Lᴴ = A`, and the incremental solve matches a dense solve.

use super::{AugmentedCholesky, DynamicLdlt, IncrementalCholesky, Marginal, MAX_RANK};
use crate::sparse::{Scalar, UpperCsc};
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

trait FromParts: Scalar {
    fn from_parts(re: f64, im: f64) -> Self;
}
impl FromParts for f64 {
    fn from_parts(re: f64, _: f64) -> Self {
        re
    }
}
impl FromParts for c64 {
    fn from_parts(re: f64, im: f64) -> Self {
        c64::new(re, im)
    }
}

fn to_c(v: &[Vec<impl Scalar>]) -> DMatrix<c64> {
    DMatrix::from_fn(v.len(), v.len(), |i, j| v[i][j].to_c64())
}

/// A random sparse SPD start: diagonal plus a few rank-1 terms.
fn start<M: FromParts>(n: usize, seed: &[(usize, usize, f64, f64)]) -> (UpperCsc<M>, DMatrix<c64>) {
    let mut dense = DMatrix::<c64>::from_diagonal_element(n, n, c64::new(1.0, 0.0));
    for &(i, j, a, b) in seed {
        let (i, j) = (i % n, j % n);
        if i != j {
            let v = M::from_parts(a, b).to_c64();
            // A += e_i e_iᴴ + e_j e_jᴴ + v e_i e_jᴴ + conj(v) e_j e_iᴴ, kept PD by the diagonal
            dense[(i, i)] += c64::new(v.norm(), 0.0);
            dense[(j, j)] += c64::new(v.norm(), 0.0);
            dense[(i, j)] += v;
            dense[(j, i)] += v.conj();
        }
    }
    let mut entries = Vec::new();
    for c in 0..n {
        for r in 0..=c {
            let v = dense[(r, c)];
            if v.norm() > 0.0 {
                entries.push((r, c, M::from_parts(v.re, v.im)));
            }
        }
    }
    (UpperCsc::from_triplets(n, &entries), dense)
}

fn close(a: &DMatrix<c64>, b: &DMatrix<c64>, tol: f64) -> bool {
    let scale = a.iter().map(|v| v.norm()).fold(1.0, f64::max);
    a.iter().zip(b.iter()).all(|(x, y)| (x - y).norm() <= tol * scale)
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
fn downdate_undoes_an_update_exactly_enough() {
    let (a, _) = start::<f64>(8, &[(0, 3, 0.5, 0.0), (2, 7, -0.3, 0.0), (4, 5, 0.9, 0.0)]);
    let mut f = DynamicLdlt::<f64>::from_matrix(&a, &(0..8).collect::<Vec<_>>()).unwrap();
    let before = f.to_dense();
    let w = [(1, 0.7), (6, -1.2), (3, 0.4)];
    f.update(&w);
    assert!(f.nnz() > 0);
    f.downdate(&w).unwrap();
    let after = f.to_dense();
    for (r1, r2) in before.iter().zip(&after) {
        for (x, y) in r1.iter().zip(r2) {
            assert!((x - y).abs() < 1e-12);
        }
    }
}

#[test]
fn downdate_to_an_indefinite_matrix_is_refused() {
    let (a, _) = start::<f64>(3, &[]);
    let mut f = DynamicLdlt::<f64>::from_matrix(&a, &[0, 1, 2]).unwrap();
    assert!(f.downdate(&[(1, 2.0)]).is_err());
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

#[test]
fn update_walks_only_the_elimination_path() {
    // A chain 0-1-2-3-4 plus an isolated 5: updating (3, 4) must not touch
    // columns 0..3 or 5.
    let mut e = vec![];
    for i in 0..6 {
        e.push((i, i, 2.0));
    }
    for i in 0..4 {
        e.push((i, i + 1, -1.0));
    }
    let a = UpperCsc::from_triplets(6, &e);
    let mut f = DynamicLdlt::<f64>::from_matrix(&a, &(0..6).collect::<Vec<_>>()).unwrap();
    let mut touched = vec![];
    f.rank1_with(&[(3, 1.0), (4, -1.0)], 1.0, |j, _| touched.push(j))
        .unwrap();
    assert_eq!(touched, vec![3, 4]);
}

#[test]
fn rank_three_update_and_downdate_match_dense() {
    // Three vectors over scattered columns, as an edge's rows are; some
    // columns carry only some of them, so both sweeps of `eliminate` run.
    let (a, dense) = start::<f64>(12, &[(0, 5, 0.4, 0.0), (2, 9, -0.3, 0.0), (7, 11, 0.2, 0.0)]);
    let mut f = DynamicLdlt::<f64>::from_matrix(&a, &(0..12).collect::<Vec<_>>()).unwrap();
    let w0 = [(1, 0.7), (4, -1.1), (8, 0.3), (10, 0.9)];
    let w1 = [(1, -0.2), (4, 0.5), (10, 1.3)];
    let w2 = [(4, 0.8), (6, -0.6), (8, 0.4), (10, -0.5), (11, 0.2)];
    f.rank_k_with(&[&w0, &w1, &w2], 1.0, |_, _| {}).unwrap();
    let mut want = dense.clone();
    for w in [&w0[..], &w1[..], &w2[..]] {
        let mut v = DMatrix::<c64>::zeros(12, 1);
        for &(i, x) in w {
            v[i] = c64::new(x, 0.0);
        }
        want += &v * v.transpose();
    }
    assert!(close(&to_c(&f.to_dense()), &want, 1e-12));
    f.rank_k_with(&[&w0, &w1, &w2], -1.0, |_, _| {}).unwrap();
    assert!(close(&to_c(&f.to_dense()), &dense, 1e-12));
}

/// A dense-ish start (every pair within `band` coupled), so that columns
/// hold long runs of consecutive rows and the vectorised kernels run.
fn banded(n: usize, band: usize) -> (UpperCsc<f64>, DMatrix<c64>) {
    let seed: Vec<_> = (0..n)
        .flat_map(|i| (i + 1..(i + band).min(n)).map(move |j| (i, j, 0.3 / (1 + j - i) as f64, 0.0)))
        .collect();
    start::<f64>(n, &seed)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Multiple-rank updates, then the same downdates, on factors with long
    /// runs, from both kinds of fresh factor: `L D Lᴴ` tracks `A`.
    #[test]
    fn rank_k_updates_on_long_runs_match_dense(
        n in 8usize..48,
        band in 2usize..24,
        supernodal in any::<bool>(),
        updates in prop::collection::vec(
            prop::collection::vec(prop::collection::vec((0usize..48, -1.0..1.0f64), 1..14), 1..=MAX_RANK),
            1..6,
        ),
    ) {
        let (a, dense) = banded(n, band);
        let kind = if supernodal { SupernodalThreshold::FORCE_SUPERNODAL } else { SupernodalThreshold::FORCE_SIMPLICIAL };
        let identity: Vec<usize> = (0..n).collect();
        let mut f = DynamicLdlt::<f64>::from_matrix_with(&a, &identity, kind).unwrap();
        prop_assert!(close(&to_c(&f.to_dense()), &dense, 1e-12), "fresh factor differs");
        let mut want = dense.clone();
        let mut ws_all = Vec::new();
        for vectors in updates {
            let ws: Vec<Vec<(usize, f64)>> = vectors
                .into_iter()
                .map(|v| {
                    let mut w: Vec<(usize, f64)> = Vec::new();
                    for (i, x) in v {
                        if !w.iter().any(|&(j, _)| j == i % n) {
                            w.push((i % n, x));
                        }
                    }
                    w
                })
                .collect();
            let refs: Vec<&[(usize, f64)]> = ws.iter().map(|w| &w[..]).collect();
            f.rank_k_with(&refs, 1.0, |_, _| {}).unwrap();
            for w in &ws {
                let mut v = DMatrix::<c64>::zeros(n, 1);
                for &(i, x) in w {
                    v[i] = c64::new(x, 0.0);
                }
                want += &v * v.transpose();
            }
            prop_assert!(close(&to_c(&f.to_dense()), &want, 1e-10), "update drifted");
            ws_all.push(ws);
        }
        for ws in ws_all.iter().rev() {
            let refs: Vec<&[(usize, f64)]> = ws.iter().map(|w| &w[..]).collect();
            f.rank_k_with(&refs, -1.0, |_, _| {}).unwrap();
        }
        prop_assert!(close(&to_c(&f.to_dense()), &dense, 1e-9), "downdates did not undo the updates");
    }
}

/// Sparse vectors with their tails (their entries in the augmented row).
type Vectors = Vec<(Vec<(usize, f64)>, f64)>;

/// One change to an augmented system `[A b; bᵀ β]`.
#[derive(Clone, Debug)]
enum AugOp {
    Append,
    /// Up to three vectors with their tails, in one walk.
    Update(Vectors),
    /// Downdate of the update applied `k` ops back (mod the applied count).
    UndoUpdate(usize),
    Cost(f64),
}

fn aug_op() -> impl Strategy<Value = AugOp> {
    let vector = (
        prop::collection::vec((0usize..64, -2.0..2.0f64), 1..6),
        -3.0..3.0f64,
    );
    prop_oneof![
        1 => Just(AugOp::Append),
        4 => prop::collection::vec(vector, 1..=3).prop_map(AugOp::Update),
        2 => (0usize..64).prop_map(AugOp::UndoUpdate),
        1 => (0.0..5.0f64).prop_map(AugOp::Cost),
    ]
}

/// `[w; tail]` as distinct-index sparse vectors modulo `n`.
fn distinct(vectors: Vectors, n: usize) -> Vectors {
    vectors
        .into_iter()
        .map(|(v, tail)| {
            let mut w: Vec<(usize, f64)> = Vec::new();
            for (i, x) in v {
                if !w.iter().any(|&(j, _)| j == i % n) {
                    w.push((i % n, x));
                }
            }
            (w, tail)
        })
        .collect()
}

/// `M += σ Σ [w; tail][w; tail]ᵀ` on a dense augmented matrix (last row and
/// column are `b` and `β`).
fn add_augmented(m: &mut DMatrix<f64>, vectors: &Vectors, sigma: f64) {
    let n = m.nrows() - 1;
    for (w, tail) in vectors {
        let mut v = nalgebra::DVector::<f64>::zeros(n + 1);
        for &(i, x) in w {
            v[i] = x;
        }
        v[n] = *tail;
        *m += sigma * &v * v.transpose();
    }
}

fn run_augmented(
    n: usize,
    seed: Vec<(usize, usize, f64, f64)>,
    b0: Vec<f64>,
    ops: Vec<AugOp>,
) -> Result<(), TestCaseError> {
    let (a, dense) = start::<f64>(n, &seed);
    let b: Vec<f64> = (0..n).map(|i| b0[i % b0.len()]).collect();
    let beta = 10.0 + b.iter().map(|v| v * v).sum::<f64>();
    // M = [A b; bᵀ β]; only its A and b parts must be positive definite
    let mut m = DMatrix::<f64>::zeros(n + 1, n + 1);
    for i in 0..n {
        for j in 0..n {
            m[(i, j)] = dense[(i, j)].re;
        }
        m[(i, n)] = b[i];
        m[(n, i)] = b[i];
    }
    m[(n, n)] = beta;
    let identity: Vec<usize> = (0..n).collect();
    let f = DynamicLdlt::<f64>::from_matrix(&a, &identity).map_err(|e| TestCaseError::fail(e.to_string()))?;
    let mut chol = AugmentedCholesky::new(f, &b, beta);
    let mut applied: Vec<Vectors> = Vec::new();
    for op in ops {
        let n = chol.len();
        match op {
            AugOp::Append => {
                chol.append();
                m = m.insert_row(n, 0.0).insert_column(n, 0.0);
                // a new variable needs weight before it can be solved
                let vectors = vec![(vec![(n, 1.0)], 0.5)];
                update(&mut chol, &vectors, 1.0)?;
                add_augmented(&mut m, &vectors, 1.0);
                applied.push(vectors);
            }
            AugOp::Update(vectors) => {
                let vectors = distinct(vectors, n);
                update(&mut chol, &vectors, 1.0)?;
                add_augmented(&mut m, &vectors, 1.0);
                applied.push(vectors);
            }
            AugOp::UndoUpdate(k) if !applied.is_empty() => {
                let vectors = applied.remove(k % applied.len());
                let mut trial = m.clone();
                add_augmented(&mut trial, &vectors, -1.0);
                // only undo what leaves A positive definite
                if trial
                    .view((0, 0), (n, n))
                    .clone_owned()
                    .cholesky()
                    .is_some_and(|c| c.l().diagonal().iter().all(|d| *d > 1e-3))
                {
                    update(&mut chol, &vectors, -1.0)?;
                    m = trial;
                }
            }
            AugOp::UndoUpdate(_) => {}
            AugOp::Cost(v) => {
                chol.add_cost(v);
                m[(n, n)] += v;
            }
        }
        let n = chol.len();
        let a = m.view((0, 0), (n, n)).clone_owned();
        let b = m.view((0, n), (n, 1)).clone_owned();
        let got = DMatrix::from_fn(n, n, |i, j| chol.factor().to_dense()[i][j]);
        prop_assert!(
            close(&got.map(|v| c64::new(v, 0.0)), &a.map(|v| c64::new(v, 0.0)), 1e-9),
            "factor drifted from A"
        );
        chol.solve(0.0);
        let want = a.clone().cholesky().expect("SPD").solve(&b);
        let scale = want.iter().map(|v| v.abs()).fold(1.0, f64::max);
        for (got, want) in chol.x().iter().zip(want.iter()) {
            prop_assert!((got - want).abs() <= 1e-8 * scale, "x {got} vs {want}");
        }
        let delta = m[(n, n)] - (b.transpose() * &want)[0];
        prop_assert!(
            (chol.residual() - delta).abs() <= 1e-8 * m[(n, n)].abs().max(1.0),
            "δ {} vs {delta}",
            chol.residual()
        );
    }
    Ok(())
}

fn update(
    chol: &mut AugmentedCholesky<f64>,
    vectors: &[(Vec<(usize, f64)>, f64)],
    sigma: f64,
) -> Result<(), TestCaseError> {
    let ws: Vec<&[(usize, f64)]> = vectors.iter().map(|(w, _)| &w[..]).collect();
    let tails: Vec<f64> = vectors.iter().map(|(_, t)| *t).collect();
    chol.rank_k(&ws, &tails, sigma)
        .map_err(|e| TestCaseError::fail(e.to_string()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// The augmented row and pivot ride along every walk: after any
    /// sequence of appends, updates with tails, downdates and cost changes,
    /// `x = A⁻¹ b` and `δ = β − bᵀ A⁻¹ b` match a dense solve.
    #[test]
    fn augmented_updates_match_dense(
        n in 1usize..20,
        seed in prop::collection::vec((0usize..40, 0usize..40, -1.0..1.0f64, -1.0..1.0f64), 0..30),
        b in prop::collection::vec(-2.0..2.0f64, 1..8),
        ops in prop::collection::vec(aug_op(), 1..40),
    ) {
        run_augmented(n, seed, b, ops)?;
    }
}

#[test]
fn augmented_zero_pivots_absorb_whole_vectors() {
    // A new variable's first update carries a tail: the variable absorbs
    // it, so x moves and δ does not (the residual is explained exactly).
    let (a, _) = start::<f64>(2, &[]);
    let mut chol = AugmentedCholesky::new(DynamicLdlt::from_matrix(&a, &[0, 1]).unwrap(), &[1.0, -1.0], 5.0);
    let before = chol.residual();
    assert!((before - 3.0).abs() < 1e-12, "δ = 5 − (1 + 1) = {before}");
    let k = chol.append();
    chol.rank_k(&[&[(1, 0.5), (k, 2.0)]], &[4.0], 1.0).unwrap();
    chol.solve(0.0);
    assert!((chol.residual() - before).abs() < 1e-12);
    // x_k solves 0.5 x_1 + 2 x_k = 4 with x_1 = b_1 / a_11 = −1
    assert!((chol.x()[1] + 1.0).abs() < 1e-12);
    assert!((chol.x()[k] - 2.25).abs() < 1e-12, "{}", chol.x()[k]);
}

#[test]
fn the_wildfire_recomputes_every_touched_column_however_little_its_parent_moved() {
    // A chain 0 → 1 → … → 5; an update at column 0 with a tail touches
    // the whole path. With a threshold no change reaches, nothing spreads
    // on its own account, yet every touched column must be recomputed:
    // the root barely moves while column 0 moves most.
    let n = 6;
    let mut e = vec![];
    for i in 0..n {
        e.push((i, i, 4.0));
        if i + 1 < n {
            e.push((i, i + 1, -1.0));
        }
    }
    let a = UpperCsc::<f64>::from_triplets(n, &e);
    let b = vec![1.0; n];
    let identity: Vec<usize> = (0..n).collect();
    let mut chol = AugmentedCholesky::new(DynamicLdlt::from_matrix(&a, &identity).unwrap(), &b, 10.0);
    chol.rank_k(&[&[(0, 1.0)]], &[3.0], 1.0).unwrap();
    chol.solve(1e9);
    let mut dense = DMatrix::<f64>::zeros(n, n);
    for &(i, j, v) in &e {
        dense[(i, j)] = v;
        dense[(j, i)] = v;
    }
    dense[(0, 0)] += 1.0;
    let mut rhs = nalgebra::DVector::from_vec(b);
    rhs[0] += 3.0;
    let want = dense.cholesky().unwrap().solve(&rhs);
    for j in 0..n {
        assert!(
            (chol.x()[j] - want[j]).abs() < 1e-12,
            "x_{j} {} vs {}",
            chol.x()[j],
            want[j]
        );
    }
}

#[test]
fn vectors_on_separate_branches_walk_their_own_paths_and_join() {
    // Elimination tree 0 → 1 → 4 → 5 and 2 → 3 → 4: one vector starts on
    // each branch. Each climbs its own branch; they join at 4 and sweep
    // 4 and 5 once: six columns stepped, no fill, the dense result.
    let mut e = vec![];
    for i in 0..6 {
        e.push((i, i, 3.0));
    }
    for (i, j) in [(0, 1), (1, 4), (2, 3), (3, 4), (4, 5)] {
        e.push((i, j, -1.0));
    }
    let a = UpperCsc::from_triplets(6, &e);
    let mut f = DynamicLdlt::<f64>::from_matrix(&a, &(0..6).collect::<Vec<_>>()).unwrap();
    let mut dense = to_c(&f.to_dense());
    let nnz = f.nnz();
    let w1 = [(0, 0.5), (1, 0.3)];
    let w2 = [(2, 0.7), (3, -0.2)];
    let mut touched = vec![];
    f.rank_k_with(&[&w1, &w2], 1.0, |j, _| touched.push(j)).unwrap();
    assert_eq!(touched, vec![0, 1, 2, 3, 4, 5]);
    assert_eq!(f.walk_stats().columns, 6);
    assert_eq!(f.nnz(), nnz, "separate paths add no fill");
    for w in [&w1, &w2] {
        let mut v = DMatrix::<c64>::zeros(6, 1);
        for &(i, x) in w.iter() {
            v[i] = c64::new(x, 0.0);
        }
        dense += &v * v.transpose();
    }
    assert!(close(&to_c(&f.to_dense()), &dense, 1e-12));
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
        v in prop::collection::vec((0usize..40, 0usize..3, -2.0..2.0f64), 1..9),
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
        let mut vectors: [Vec<(usize, f64)>; 3] = Default::default();
        let mut dense_v = DMatrix::<c64>::zeros(n, 3);
        for &(i, r, x) in &v {
            let c = i % n;
            if vectors[r].iter().all(|&(k, _)| k != c) {
                vectors[r].push((c, x));
                dense_v[(perm[c], r)] = c64::new(x, 0.0);
            }
        }
        let got = Marginal::default().form(&f, [&vectors[0], &vectors[1], &vectors[2]]).unwrap();
        let want = dense_v.adjoint() * dense.try_inverse().unwrap() * &dense_v;
        for r in 0..3 {
            for s in 0..3 {
                let scale = want[(r, r)].re.abs().max(want[(s, s)].re.abs()).max(1.0);
                prop_assert!((got[(r, s)] - want[(r, s)].re).abs() <= 1e-9 * scale, "{r},{s}: {} vs {}", got[(r, s)], want[(r, s)].re);
            }
        }
    }
}
