//! The augmented factor of `[A b; bᴴ β]`: the forward solve and the last
//! pivot ride along the walks, and the back-substitution recomputes every
//! column they touched.

use super::{close, start};
use crate::sparse::dynamic::{AugmentedCholesky, DynamicLdlt};
use crate::sparse::UpperCsc;
use faer::c64;
use nalgebra::DMatrix;
use proptest::prelude::*;

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
