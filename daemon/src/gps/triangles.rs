//! Paper A's GPS equations (§4.2), with the printed errors fixed.
//!
//! Three fixes `a, b, c` at metric positions `G_a, G_b, G_c` give the
//! similar-triangle equation `p_c − p_b = ω (p_a − p_b)` on the keyframes'
//! positions, with `ω = (G_c − G_b) / (G_a − G_b)` computed as a complex
//! quotient (error 1: an arccos loses the angle's sign). Its variance is the
//! sum of the two GPS vectors' variances, `σ_ab² + σ_cb²` with
//! `σ_ab² = σ_a² + σ_b²`.
//!
//! - **Adjacent triples** `g_i, g_{i+1}, g_{i+2}` give an equation when no
//!   two of them coincide: every side longer than ε (error 2: the printed
//!   test keeps exactly the triples it should drop).
//! - **Wide triangles**: random triples from a seeded RNG, kept when every
//!   long/short side ratio is below `p_thres` (the printed tests are
//!   inverted there too; a failed test skips the triple and goes on),
//!   until `Δ_req` are found or `f_max` draws are spent.

use super::GpsFix;
use faer::c64;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The rules' parameters (the daemon's `[gps]` configuration).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TriangleParams {
    /// Fixes closer than this (m) coincide.
    pub eps: f64,
    /// A wide triangle's long/short side ratios must stay below this.
    pub p_thres: f64,
    /// Wide triangles wanted.
    pub delta_req: usize,
    /// Random draws allowed.
    pub f_max: usize,
    /// RNG seed: the same fixes and seed give the same triangles.
    pub seed: u64,
}

impl Default for TriangleParams {
    fn default() -> Self {
        Self {
            eps: 0.5,
            p_thres: 3.0,
            delta_req: 200,
            f_max: 20_000,
            seed: 1,
        }
    }
}

/// One equation `p_c − p_b = ω (p_a − p_b)` on fixes `a, b, c` (indices
/// into the fix list).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// First fix.
    pub a: usize,
    /// The pivot fix.
    pub b: usize,
    /// Third fix.
    pub c: usize,
    /// `(G_c − G_b) / (G_a − G_b)`.
    pub omega: c64,
    /// `σ_ab² + σ_cb²`.
    pub variance: f64,
}

/// The three side lengths of a triangle.
fn sides(g: [c64; 3]) -> [f64; 3] {
    [(g[0] - g[1]).norm(), (g[1] - g[2]).norm(), (g[2] - g[0]).norm()]
}

/// Rule: no two points coincide (every side longer than ε).
pub fn distinct(g: [c64; 3], eps: f64) -> bool {
    sides(g).iter().all(|&s| s > eps)
}

/// Rule: every long/short side ratio below `p_thres` (no sliver).
pub fn well_shaped(g: [c64; 3], p_thres: f64) -> bool {
    let s = sides(g);
    let longest = s.iter().fold(0.0f64, |m, &v| m.max(v));
    let shortest = s.iter().fold(f64::MAX, |m, &v| m.min(v));
    shortest > 0.0 && longest / shortest < p_thres
}

fn triangle(fixes: &[GpsFix], a: usize, b: usize, c: usize) -> Triangle {
    let (ga, gb, gc) = (fixes[a].enu, fixes[b].enu, fixes[c].enu);
    let (va, vb, vc) = (fixes[a].variance(), fixes[b].variance(), fixes[c].variance());
    Triangle {
        a,
        b,
        c,
        omega: (gc - gb) / (ga - gb),
        variance: (va + vb) + (vc + vb),
    }
}

/// Equations over consecutive fixes (in the given order).
pub fn adjacent(fixes: &[GpsFix], params: &TriangleParams) -> Vec<Triangle> {
    (2..fixes.len())
        .filter(|&i| distinct([fixes[i - 2].enu, fixes[i - 1].enu, fixes[i].enu], params.eps))
        .map(|i| triangle(fixes, i - 2, i - 1, i))
        .collect()
}

/// Seeded random wide triangles.
pub fn wide(fixes: &[GpsFix], params: &TriangleParams) -> Vec<Triangle> {
    let n = fixes.len();
    let mut out = Vec::new();
    if n < 3 {
        return out;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    for _ in 0..params.f_max {
        if out.len() >= params.delta_req {
            break;
        }
        let (a, b, c) = (
            rng.random_range(0..n),
            rng.random_range(0..n),
            rng.random_range(0..n),
        );
        if a == b || b == c || a == c {
            continue;
        }
        let g = [fixes[a].enu, fixes[b].enu, fixes[c].enu];
        if distinct(g, params.eps) && well_shaped(g, params.p_thres) {
            out.push(triangle(fixes, a, b, c));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    fn fix(k: usize, x: f64, y: f64) -> GpsFix {
        GpsFix {
            keyframe: k,
            enu: c64::new(x, y),
            covariance: Matrix2::identity(),
            up: 0.0,
            up_variance: 0.0,
        }
    }

    #[test]
    fn coincident_fixes_give_no_adjacent_equation() {
        // 0 and 1 coincide (within ε = 0.5); 1, 2, 3 are distinct
        let fixes = [
            fix(0, 0.0, 0.0),
            fix(1, 0.3, 0.0),
            fix(2, 5.0, 0.0),
            fix(3, 5.0, 5.0),
        ];
        let t = adjacent(&fixes, &TriangleParams::default());
        assert_eq!(t.len(), 1);
        assert_eq!((t[0].a, t[0].b, t[0].c), (1, 2, 3));
        assert!(distinct(
            [c64::new(0.0, 0.0), c64::new(1.0, 0.0), c64::new(0.0, 1.0)],
            0.5
        ));
        assert!(!distinct(
            [c64::new(0.0, 0.0), c64::new(0.4, 0.0), c64::new(0.0, 1.0)],
            0.5
        ));
    }

    #[test]
    fn omega_carries_the_angle_with_its_sign() {
        // a right turn and a left turn differ in the sign of arg ω
        let left = [fix(0, 1.0, 0.0), fix(1, 0.0, 0.0), fix(2, 0.0, 1.0)];
        let right = [fix(0, 1.0, 0.0), fix(1, 0.0, 0.0), fix(2, 0.0, -1.0)];
        let (l, r) = (
            adjacent(&left, &TriangleParams::default()),
            adjacent(&right, &TriangleParams::default()),
        );
        assert!((l[0].omega - c64::new(0.0, 1.0)).norm() < 1e-15);
        assert!((r[0].omega - c64::new(0.0, -1.0)).norm() < 1e-15);
        assert_eq!(l[0].variance, 4.0);
    }

    #[test]
    fn slivers_fail_the_side_ratio_test() {
        let equilateral = [
            c64::new(0.0, 0.0),
            c64::new(1.0, 0.0),
            c64::from_polar(1.0, std::f64::consts::FRAC_PI_3),
        ];
        assert!(well_shaped(equilateral, 3.0));
        let sliver = [c64::new(0.0, 0.0), c64::new(10.0, 0.0), c64::new(5.0, 0.2)];
        // sides 10, ~5.004, ~5.004: ratio ~2 passes; a shorter third side fails
        assert!(well_shaped(sliver, 3.0));
        let thin = [c64::new(0.0, 0.0), c64::new(10.0, 0.0), c64::new(9.0, 0.0)];
        assert!(!well_shaped(thin, 3.0), "sides 10, 1, 9: ratio 10");
    }

    #[test]
    fn wide_triangles_are_reproducible_from_their_seed() {
        let fixes: Vec<GpsFix> = (0..40)
            .map(|k| fix(k, (k % 7) as f64 * 3.0, (k / 7) as f64 * 4.0))
            .collect();
        let p = TriangleParams {
            delta_req: 25,
            ..Default::default()
        };
        let (a, b) = (wide(&fixes, &p), wide(&fixes, &p));
        assert_eq!(a.len(), 25);
        assert_eq!(a, b);
        let c = wide(&fixes, &TriangleParams { seed: 2, ..p });
        assert_ne!(a, c);
        for t in &a {
            let g = [fixes[t.a].enu, fixes[t.b].enu, fixes[t.c].enu];
            assert!(distinct(g, p.eps) && well_shaped(g, p.p_thres));
        }
    }
}
