//! The 3-D two-stage initialiser: chordal rotations, then positions.
//!
//! Paper A's virtual points along each pose's axes make the rotation
//! stage linear in the axes; in space that is the chordal relaxation
//! (Martinec and Pajdla 2007; Carlone, Tron, Daniilidis and Dellaert,
//! ICRA 2015), the initialiser GTSAM's `InitializePose3` also uses.
//!
//! - **Rotations.** `R_j − R_i R_ij = 0` for every edge, `R_0 = I`. Row `k`
//!   of `R_j` is row `k` of `R_i` times `R_ij`, so with `ρ_i` that row as a
//!   column, `ρ_j − R_ijᵀ ρ_i = 0`: one sparse SPD system with 3×3 blocks
//!   and three right-hand sides (one per row), weighted by the edge's
//!   isotropic rotational information. Each solved matrix is projected onto
//!   SO(3) by SVD.
//! - **Positions.** `p_j − p_i = R_i t_ij`, `p_0 = 0`, weighted by the
//!   translational information turned into the map frame,
//!   `W = R_i R_ij Ω_t R_ijᵀ R_iᵀ`.
//!
//! Both normal matrices have the pose graph's pattern in 3×3 blocks, so
//! one fill-reducing order serves them.

use crate::graph::{pose_ordering, Edge, Pose3, PoseGraph};
use crate::sparse::ordering::expand_blocks;
use crate::sparse::{FactorError, Ordering, SparseCholesky, UpperCsc};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Normal equations over `3(n − 1)` unknowns (keyframe 0 fixed), built
/// from 3×3 blocks.
struct BlockSystem {
    entries: Vec<(usize, usize, f64)>,
    rhs: Vec<Vec<f64>>,
}

impl BlockSystem {
    fn new(n: usize, columns: usize) -> Self {
        Self {
            entries: Vec::new(),
            rhs: vec![vec![0.0; 3 * n.saturating_sub(1)]; columns],
        }
    }

    /// Adds block `m` at block row `i`, column `j` (keyframe indices,
    /// both free), keeping the upper triangle.
    fn block(&mut self, i: usize, j: usize, m: &Matrix3<f64>) {
        let (bi, bj) = (3 * (i - 1), 3 * (j - 1));
        for r in 0..3 {
            for c in 0..3 {
                let (row, col) = (bi + r, bj + c);
                if row <= col {
                    self.entries.push((row, col, m[(r, c)]));
                }
            }
        }
    }

    /// Adds the rows of `a x_j − b x_i = y` with weight `w` (SPD) to the
    /// normal equations, for each right-hand side `y[k]`; a keyframe 0 term
    /// is known (`x_0 = x0[k]`) and moved to the right.
    fn relation(
        &mut self,
        i: usize,
        j: usize,
        b: &Matrix3<f64>,
        w: &Matrix3<f64>,
        y: &[Vector3<f64>],
        x0: &[Vector3<f64>],
    ) {
        // residual r = x_j − B x_i − y
        let wb = w * b;
        if j > 0 {
            self.block(j, j, w);
        }
        if i > 0 {
            self.block(i, i, &(b.transpose() * wb));
        }
        if i > 0 && j > 0 {
            if i < j {
                self.block(i, j, &-(wb.transpose()));
            } else {
                self.block(j, i, &-wb);
            }
        }
        for (k, rhs) in self.rhs.iter_mut().enumerate() {
            let mut known = y[k];
            if i == 0 {
                known += b * x0[k];
            }
            if j == 0 {
                known -= x0[k];
            }
            // x_j − B x_i = known
            if j > 0 {
                let g = w * known;
                for r in 0..3 {
                    rhs[3 * (j - 1) + r] += g[r];
                }
            }
            if i > 0 {
                let g = -(wb.transpose() * known);
                for r in 0..3 {
                    rhs[3 * (i - 1) + r] += g[r];
                }
            }
        }
    }

    /// Solves for every right-hand side.
    fn solve(self, n: usize, order: &[usize]) -> Result<Vec<Vec<f64>>, FactorError> {
        let a = UpperCsc::from_triplets(3 * n.saturating_sub(1), &self.entries);
        let mut factor = SparseCholesky::new(&a, &Ordering::Custom(expand_blocks(order, 3)))?;
        Ok(self.rhs.iter().map(|b| factor.solve(b)).collect())
    }
}

/// The nearest rotation to `m` in the Frobenius norm.
pub fn project_to_rotation(m: &Matrix3<f64>) -> Rotation3<f64> {
    let svd = m.svd(true, true);
    let (u, v_t) = (
        svd.u.unwrap_or_else(Matrix3::identity),
        svd.v_t.unwrap_or_else(Matrix3::identity),
    );
    let d = (u * v_t).determinant().signum();
    Rotation3::from_matrix_unchecked(u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t)
}

/// Stage 1: the rotation of every keyframe, `R_0 = I`.
pub fn solve_rotations(
    graph: &PoseGraph<Pose3>,
    order: &[usize],
) -> Result<Vec<Rotation3<f64>>, FactorError> {
    let n = graph.len();
    let mut system = BlockSystem::new(n, 3);
    let rows0 = [Vector3::x(), Vector3::y(), Vector3::z()];
    let zero = [Vector3::zeros(); 3];
    for e in graph.edges() {
        let m = e.measurement.rotation_matrix().into_inner().transpose();
        let w = Matrix3::from_diagonal_element(e.information.rotation_weight());
        system.relation(e.from, e.to, &m, &w, &zero, &rows0);
    }
    let rows = system.solve(n, order)?;
    let mut rotations = vec![Rotation3::identity(); n];
    for (k, r) in rotations.iter_mut().enumerate().skip(1) {
        let o = 3 * (k - 1);
        let m = Matrix3::from_fn(|row, c| rows[row][o + c]);
        *r = project_to_rotation(&m);
    }
    Ok(rotations)
}

/// The map-frame weight of an edge's translation: `R_i R_ij Ω_t R_ijᵀ R_iᵀ`.
fn map_frame_weight(edge: &Edge<Pose3>, r_i: &Rotation3<f64>) -> Matrix3<f64> {
    let r = r_i.matrix() * edge.measurement.rotation_matrix().matrix();
    r * edge.information.translation_information() * r.transpose()
}

/// Stage 2: positions given the rotations, `p_0 = 0`.
pub fn solve_positions(
    graph: &PoseGraph<Pose3>,
    rotations: &[Rotation3<f64>],
    order: &[usize],
) -> Result<Vec<Vector3<f64>>, FactorError> {
    let n = graph.len();
    let mut system = BlockSystem::new(n, 1);
    let zero = [Vector3::zeros()];
    for e in graph.edges() {
        let w = map_frame_weight(e, &rotations[e.from]);
        let y = [rotations[e.from] * e.measurement.translation];
        system.relation(e.from, e.to, &Matrix3::identity(), &w, &y, &zero);
    }
    let x = system.solve(n, order)?.remove(0);
    Ok((0..n)
        .map(|k| match k {
            0 => Vector3::zeros(),
            _ => Vector3::new(x[3 * (k - 1)], x[3 * (k - 1) + 1], x[3 * (k - 1) + 2]),
        })
        .collect())
}

/// Both stages: the linear initial guess of a 3-D graph.
pub fn solve(graph: &PoseGraph<Pose3>) -> Result<Vec<Pose3>, FactorError> {
    let order = pose_ordering(graph.len(), graph.edges());
    let rotations = solve_rotations(graph, &order)?;
    let positions = solve_positions(graph, &rotations, &order)?;
    Ok(positions
        .into_iter()
        .zip(&rotations)
        .map(|(p, r)| Pose3::new(p, UnitQuaternion::from_rotation_matrix(r)))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{chi2, EdgeKind, Information6};

    /// A noise-free loop: the chain of a helix plus a closure back to the
    /// start, solved exactly.
    #[test]
    fn recovers_a_noise_free_loop() {
        let truth: Vec<Pose3> = (0..12)
            .map(|k| {
                let a = k as f64 * 0.5;
                Pose3::from_xyz_rpy([
                    3.0 * a.cos(),
                    3.0 * a.sin(),
                    0.2 * k as f64,
                    0.1 * a.sin(),
                    -0.05 * k as f64,
                    a + 1.5,
                ])
            })
            .collect();
        let mut g = PoseGraph::<Pose3>::default();
        for k in 0..truth.len() {
            g.add_keyframe(k as u64, None).unwrap();
        }
        let pairs = (1..truth.len()).map(|k| (k - 1, k)).chain([(0, 11), (3, 9)]);
        for (i, j) in pairs {
            let z = truth[i].between(&truth[j]);
            let kind = EdgeKind::from_ids(i as u64, j as u64);
            g.add_edge(i as u64, j as u64, z, Information6::identity(), kind)
                .unwrap();
        }
        let poses = solve(&g).unwrap();
        let anchored: Vec<Pose3> = truth.iter().map(|t| truth[0].between(t)).collect();
        for (p, t) in poses.iter().zip(&anchored) {
            assert!((p.translation - t.translation).norm() < 1e-9, "{p:?} vs {t:?}");
            assert!(p.rotation.angle_to(&t.rotation) < 1e-9);
        }
        assert!(chi2(&g, &poses) < 1e-18);
    }

    #[test]
    fn projection_keeps_rotations_and_fixes_scaled_ones() {
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
        let p = project_to_rotation(&(r.matrix() * 0.4));
        assert!((p.matrix() - r.matrix()).norm() < 1e-12);
        assert!((project_to_rotation(&-Matrix3::identity()).matrix().determinant() - 1.0).abs() < 1e-12);
    }
}
