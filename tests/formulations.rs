//! Every formulation recovers noise-free graphs exactly (to 1e-9): chains,
//! grids, loops and exactly degenerate triangles.

use proptest::prelude::*;
use slamd::geometry::Pose2;
use slamd::solver::{solve_batch, BatchOptions, Formulation};
use slamd_tests::{max_pose_error, noise_free, walk};
use std::f64::consts::PI;

const TOL: f64 = 1e-9;

fn check_all(truth: &[Pose2], pairs: &[(usize, usize)]) -> Result<(), TestCaseError> {
    let g = noise_free(truth, pairs);
    for formulation in Formulation::ALL {
        for polish in [false, true] {
            let opts = BatchOptions {
                formulation,
                polish,
                ..Default::default()
            };
            let s = solve_batch(&g, &opts).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let err = max_pose_error(&s.poses, truth);
            prop_assert!(err < TOL, "{formulation} polish={polish}: error {err:e}");
            prop_assert!(s.chi2 < 1e-12, "{formulation} polish={polish}: chi2 {}", s.chi2);
        }
    }
    Ok(())
}

/// One random step of a walk.
fn step() -> impl Strategy<Value = (f64, f64, f64)> {
    (-2.0..2.0f64, -2.0..2.0f64, -PI..PI)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn chains_with_random_loops(steps in prop::collection::vec(step(), 2..40), loops in prop::collection::vec((0usize..1000, 0usize..1000), 0..15)) {
        let truth = walk(&steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.extend(loops.into_iter().map(|(a, b)| (a % n, b % n)).filter(|(a, b)| a != b));
        check_all(&truth, &pairs)?;
    }

    #[test]
    fn grids(w in 2usize..7, h in 2usize..7, spacing in 0.5..3.0f64, yaw in prop::collection::vec(-PI..PI, 49)) {
        let truth: Vec<Pose2> = (0..w * h)
            .map(|k| if k == 0 { Pose2::IDENTITY } else { Pose2::new((k % w) as f64 * spacing, (k / w) as f64 * spacing, yaw[k]) })
            .collect();
        let mut pairs = Vec::new();
        for k in 0..w * h {
            if k % w + 1 < w { pairs.push((k, k + 1)); }
            if k + w < w * h { pairs.push((k, k + w)); }
        }
        check_all(&truth, &pairs)?;
    }

    #[test]
    fn newer_first_loops(steps in prop::collection::vec(step(), 3..20)) {
        let truth = walk(&steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.push((n - 1, 0));
        pairs.push((n - 1, n / 2));
        check_all(&truth, &pairs)?;
    }

    /// Edges whose neighbour's virtual point lands exactly on `i_x` or `i_y`:
    /// paper A's degenerate cases, where ω has a zero or a pole.
    #[test]
    fn exactly_degenerate_triangles(thetas in prop::collection::vec(-PI..PI, 4..12), kinds in prop::collection::vec(0usize..5, 12)) {
        // In frame i, j_x = t + e^{iθ} and j_y = t + i e^{iθ}. Choosing t puts
        // one of them exactly on 1 (= i_x) or i (= i_y).
        let mut steps = Vec::new();
        for (k, &th) in thetas.iter().enumerate() {
            let (c, s) = (th.cos(), th.sin());
            let (x, y) = match kinds[k] {
                0 => (1.0 - c, -s),        // j_x = i_x
                1 => (-c, 1.0 - s),        // j_x = i_y
                2 => (1.0 + s, -c),        // j_y = i_x
                3 => (s, 1.0 - c),         // j_y = i_y
                _ => (0.0, 0.0),           // co-located keyframes
            };
            steps.push((x, y, if kinds[k] == 4 { 0.0 } else { th }));
        }
        let truth = walk(&steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.push((0, n - 1));
        check_all(&truth, &pairs)?;
    }
}

#[test]
fn degenerate_steps_really_hit_the_degenerate_branch() {
    // The strategies above are only meaningful if the constructed t gives
    // |1 − j_x| below the threshold after the round trip through Pose2.
    let th: f64 = 0.7;
    let step = Pose2::new(1.0 - th.cos(), -th.sin(), th);
    let jx = step.position() + step.rotation();
    assert!((jx.re - 1.0).hypot(jx.im) < slamd::linear::virtual_frame::DEGENERATE_EPS);
}
