//! [`LinearStages`]: the two-stage linear solution, kept exact as the graph
//! grows.
//!
//! Both stages have fixed normal matrices (docs/design.md, "Two stages:
//! axes, then positions"), so a new edge is a rank-1 update of each
//! factor, a reweight a rank-1 update or downdate, and a new keyframe an
//! appended column:
//! - axes: `r_j − e^{iθ_ij} r_i = 0`, weight `s/σθ²`, `r_gauge = 1`;
//! - positions: `p_j − p_i = r_i t_ij`, weight `s·2/tr Σ_t` (the scalar,
//!   data-independent Laplacian), `p_gauge = 0`.
//!
//! Only the position stage's right-hand side depends on the axes; when an
//! axis changes, the rows of the edges leaving that keyframe are corrected.
//! Solved with threshold 0 this equals a batch two-stage solve with
//! isotropic weights of the same edges (property-tested to 1e-9).

use crate::geometry::Pose2;
use crate::graph::{Edge, PoseGraph};
use crate::linear::two_stage::normalise;
use crate::linear::{LinearSystem, Var};
use crate::sparse::dynamic::{DynamicLdlt, IncrementalCholesky, UpdateError};
use crate::sparse::{FactorError, Scalar};
use faer::c64;

const NONE: u32 = u32::MAX;
const ONE: c64 = c64 { re: 1.0, im: 0.0 };
const ZERO: c64 = c64 { re: 0.0, im: 0.0 };

/// The incremental two-stage system over the keyframes that have joined.
#[derive(Clone, Debug)]
pub struct LinearStages {
    column: Vec<u32>,
    keyframe_of: Vec<u32>,
    axes: IncrementalCholesky<c64, c64>,
    positions: IncrementalCholesky<f64, c64>,
    /// The normalised axis each keyframe's outgoing position rows were
    /// written with.
    axis: Vec<c64>,
    /// Applied edges by their `from` keyframe, with their current scale.
    outgoing: Vec<Vec<(u32, f64)>>,
    /// The current solution `(p_k, arg r_k)` of every keyframe slot.
    poses: Vec<Pose2>,
    changed: Vec<usize>,
    stamp: Vec<u32>,
    epoch: u32,
}

/// A row's terms over columns and its right-hand side, gauge folded in.
fn row_terms<M: Scalar>(
    column: &[u32],
    terms: [(usize, M); 2],
    gauge: c64,
    rhs: c64,
) -> ([(Var, M); 2], c64) {
    let var = |k: usize| match column[k] {
        NONE => Var::Fixed(gauge),
        c => Var::Free(c as usize),
    };
    (
        [(var(terms[0].0), terms[0].1), (var(terms[1].0), terms[1].1)],
        rhs,
    )
}

impl LinearStages {
    /// An empty system holding only the gauge keyframe (index 0).
    pub fn new() -> Self {
        Self {
            column: vec![NONE],
            keyframe_of: Vec::new(),
            axes: IncrementalCholesky::empty(),
            positions: IncrementalCholesky::empty(),
            axis: vec![ONE],
            outgoing: vec![Vec::new()],
            poses: vec![Pose2::IDENTITY],
            changed: Vec::new(),
            stamp: vec![0],
            epoch: 0,
        }
    }

    /// A fresh factorisation: keyframes `order` (the gauge excluded) in
    /// elimination order, `edges` with their scales. Keyframes not in
    /// `order` and not the gauge have not joined yet.
    pub fn build(graph: &PoseGraph, edges: &[(usize, f64)], order: &[usize]) -> Result<Self, FactorError> {
        let n = graph.len();
        let mut s = Self::new();
        s.column = vec![NONE; n];
        s.axis = vec![ONE; n];
        s.outgoing = vec![Vec::new(); n];
        s.poses = vec![Pose2::IDENTITY; n];
        s.stamp = vec![0; n];
        for (c, &k) in order.iter().enumerate() {
            s.column[k] = c as u32;
        }
        s.keyframe_of = order.iter().map(|&k| k as u32).collect();
        let m = order.len();
        let identity: Vec<usize> = (0..m).collect();

        let mut axes = LinearSystem::<c64>::new(m);
        for &(e, scale) in edges {
            let (terms, rhs, w) = s.axis_row(&graph.edges()[e], scale);
            axes.push(&terms, rhs, w);
        }
        let (a, b) = axes.normal_equations();
        s.axes = IncrementalCholesky::new(DynamicLdlt::from_matrix(&a, &identity)?, b);
        s.refresh_axes();

        let mut positions = LinearSystem::<f64>::new(m);
        for &(e, scale) in edges {
            let edge = &graph.edges()[e];
            let (terms, rhs, w) = s.position_row(edge, scale);
            positions.push(&terms, rhs, w);
            s.outgoing[edge.from].push((e as u32, scale));
        }
        let (a, b) = positions.normal_equations();
        s.positions = IncrementalCholesky::new(DynamicLdlt::from_matrix(&a, &identity)?, b);
        for i in 0..s.keyframe_of.len() {
            s.refresh_pose(s.keyframe_of[i] as usize);
        }
        Ok(s)
    }

    fn axis_row(&self, edge: &Edge, scale: f64) -> ([(Var, c64); 2], c64, f64) {
        let z = edge.measurement.rotation();
        let (terms, rhs) = row_terms(&self.column, [(edge.to, ONE), (edge.from, -z)], ONE, ZERO);
        (terms, rhs, scale * edge.information.rotation_weight())
    }

    fn position_row(&self, edge: &Edge, scale: f64) -> ([(Var, f64); 2], c64, f64) {
        let rhs = self.axis[edge.from] * edge.measurement.position();
        let (terms, rhs) = row_terms(&self.column, [(edge.to, 1.0), (edge.from, -1.0)], ZERO, rhs);
        (terms, rhs, scale * edge.information.translation_weight())
    }

    /// Keyframe `k` joins: one new column in each stage.
    pub fn add_keyframe(&mut self, k: usize) {
        if self.column.len() <= k {
            self.column.resize(k + 1, NONE);
            self.axis.resize(k + 1, ONE);
            self.outgoing.resize(k + 1, Vec::new());
            self.poses.resize(k + 1, Pose2::IDENTITY);
            self.stamp.resize(k + 1, 0);
        }
        if k == 0 {
            return; // the gauge has no unknowns
        }
        let c = self.axes.append();
        self.positions.append();
        self.column[k] = c as u32;
        self.keyframe_of.push(k as u32);
    }

    /// Adds `delta` times the edge's rows (both ends must have joined): a
    /// new edge has `delta = 1`, a removal `−scale`, a reweight the change.
    pub fn apply_edge(&mut self, index: usize, edge: &Edge, delta: f64) -> Result<(), UpdateError> {
        let (terms, rhs, w) = self.axis_row(edge, delta);
        apply_row(&mut self.axes, &terms, rhs, w)?;
        let (terms, rhs, w) = self.position_row(edge, delta);
        apply_row(&mut self.positions, &terms, rhs, w)?;
        let out = &mut self.outgoing[edge.from];
        match out.iter_mut().find(|(e, _)| *e as usize == index) {
            Some((_, s)) => *s += delta,
            None => out.push((index as u32, delta)),
        }
        Ok(())
    }

    /// Solves both stages exactly and returns the poses of every keyframe
    /// (not-yet-joined keyframes at the origin).
    pub fn solve_exact(&mut self, graph: &PoseGraph) -> Vec<Pose2> {
        self.solve(graph, 0.0);
        self.poses.clone()
    }

    /// Solves both stages; a column whose solution moves by at most
    /// `threshold` does not pass the change to its subtree (0: exact).
    /// Returns the keyframes whose pose changed.
    pub fn solve(&mut self, graph: &PoseGraph, threshold: f64) -> &[usize] {
        self.epoch = self.epoch.wrapping_add(1);
        self.changed.clear();
        let moved_axes = self.axes.solve(threshold).to_vec();
        for c in moved_axes {
            let k = self.keyframe_of[c] as usize;
            let new = normalise(self.axes.x()[c]);
            let old = self.axis[k];
            if new == old {
                continue;
            }
            self.axis[k] = new;
            self.mark(k);
            // the position rows of edges leaving k were written with the old
            // axis: Δb = w (r_new − r_old) t at `to`, minus at `from`
            for &(e, scale) in &self.outgoing[k] {
                let edge = &graph.edges()[e as usize];
                let w = scale * edge.information.translation_weight();
                let delta = (new - old) * edge.measurement.position() * w;
                if let Some(to) = col(&self.column, edge.to) {
                    self.positions.add_rhs(to, delta);
                }
                if let Some(from) = col(&self.column, edge.from) {
                    self.positions.add_rhs(from, -delta);
                }
            }
        }
        let moved_positions = self.positions.solve(threshold).to_vec();
        for c in moved_positions {
            self.mark(self.keyframe_of[c] as usize);
        }
        for i in 0..self.changed.len() {
            self.refresh_pose(self.changed[i]);
        }
        &self.changed
    }

    fn mark(&mut self, k: usize) {
        if self.stamp[k] != self.epoch {
            self.stamp[k] = self.epoch;
            self.changed.push(k);
        }
    }

    fn refresh_pose(&mut self, k: usize) {
        if let Some(c) = col(&self.column, k) {
            self.poses[k] = Pose2::from_complex(self.positions.x()[c], self.axis[k].arg());
        }
    }

    /// Stored entries of both factors.
    pub fn factor_nnz(&self) -> usize {
        self.axes.factor().nnz() + self.positions.factor().nnz()
    }

    /// The current two-stage pose of keyframe `k` (the gauge at the origin).
    pub fn pose(&self, k: usize) -> Pose2 {
        self.poses[k]
    }

    /// Axes of the fresh solve, before any position row is written.
    fn refresh_axes(&mut self) {
        for (c, &k) in self.keyframe_of.iter().enumerate() {
            self.axis[k as usize] = normalise(self.axes.x()[c]);
        }
    }
}

impl Default for LinearStages {
    fn default() -> Self {
        Self::new()
    }
}

fn col(column: &[u32], k: usize) -> Option<usize> {
    (column[k] != NONE).then_some(column[k] as usize)
}

/// Adds `w |Σ c x − y|²` to a system: the rank-1 term `w c̄ cᵀ` (an update
/// for `w > 0`, a downdate for `w < 0`) and `w c̄ y` to the right side.
fn apply_row<M: Scalar>(
    chol: &mut IncrementalCholesky<M, c64>,
    terms: &[(Var, M)],
    mut rhs: c64,
    w: f64,
) -> Result<(), UpdateError>
where
    c64: std::ops::Mul<M, Output = c64>,
{
    for (var, coef) in terms {
        if let Var::Fixed(v) = var {
            rhs -= times(coef.to_c64(), *v);
        }
    }
    let root = w.abs().sqrt();
    let mut vec = Vec::with_capacity(terms.len());
    for &(var, coef) in terms {
        if let Var::Free(c) = var {
            vec.push((c, coef.conjugate().scale(root)));
            chol.add_rhs(c, times(coef.conjugate().to_c64(), rhs).scale(w));
        }
    }
    chol.rank1(&vec, w.signum())
}

/// `a b` outside the generic context of [`apply_row`], whose bound would
/// otherwise steer the operator to `c64 × M`.
fn times(a: c64, b: c64) -> c64 {
    a * b
}
