//! Updates and downdates of the factor: `L D Lᴴ` tracks `A`, and a walk
//! touches only the elimination-tree paths of its vectors.

use super::{close, start, to_c};
use crate::sparse::dynamic::{DynamicLdlt, MAX_RANK};
use crate::sparse::UpperCsc;
use faer::c64;
use faer::sparse::linalg::SupernodalThreshold;
use nalgebra::DMatrix;
use proptest::prelude::*;

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
