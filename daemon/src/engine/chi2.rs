//! [`Chi2Cache`]: the estimate's χ², kept edge by edge.
//!
//! `χ² = Σ_e w_e · eᵀ Ω e` over the applied edges, `w_e` the edge's weight
//! ([`Model::weight`]). A solve that moves a few keyframes refreshes only
//! the edges incident to them, each once (an epoch stamp per edge); one
//! that moves more than a quarter of the map recomputes every edge, which
//! also clears the running sum's round-off.

use super::model::Model;
use super::pose::EnginePose;
use crate::geometry::Turns;

/// Per-edge χ² at the estimate and their sum.
#[derive(Clone, Debug, Default)]
pub struct Chi2Cache {
    /// `w_e · eᵀ Ω e` of each edge (0 while not applied).
    per_edge: Vec<f64>,
    /// Rotations of the estimate's keyframes and of the edges'
    /// measurements (a moved keyframe meets several edges; a measurement
    /// never changes).
    turns: Turns,
    measured_turns: Turns,
    total: f64,
    /// The epoch in which each edge was last refreshed.
    stamp: Vec<u32>,
    epoch: u32,
}

impl Chi2Cache {
    /// The cache over `model`'s edges at `estimate`, computed.
    pub fn new<P: EnginePose>(model: &Model<P>, estimate: &[P]) -> Self {
        let edges = model.graph.edges().len();
        let mut cache = Self {
            per_edge: vec![0.0; edges],
            stamp: vec![0; edges],
            ..Self::default()
        };
        cache.recompute(model, estimate);
        cache
    }

    /// A new edge, not applied yet.
    pub fn push_edge(&mut self) {
        self.per_edge.push(0.0);
    }

    /// χ² of the estimate over the applied edges, with their weights.
    pub fn total(&self) -> f64 {
        self.total
    }

    /// Recomputes edge `e`'s term at `estimate`.
    pub fn refresh<P: EnginePose>(&mut self, model: &Model<P>, e: usize, estimate: &[P]) {
        let edge = &model.graph.edges()[e];
        let v =
            model.weight(e) * P::cached_chi2(&mut self.turns, &mut self.measured_turns, e, edge, estimate);
        self.total += v - self.per_edge[e];
        self.per_edge[e] = v;
    }

    /// Refreshes the terms of every applied edge incident to the `moved`
    /// keyframes, each once; past a quarter of the map, recomputes all.
    pub fn refresh_moved<P: EnginePose>(&mut self, model: &Model<P>, moved: &[usize], estimate: &[P]) {
        if moved.len() * 4 > model.graph.len() {
            self.recompute(model, estimate);
            return;
        }
        self.epoch = self.epoch.wrapping_add(1);
        if self.stamp.len() < self.per_edge.len() {
            self.stamp.resize(self.per_edge.len(), 0);
        }
        for &k in moved {
            for &e in &model.keyframes[k].incident {
                let e = e as usize;
                if self.stamp[e] != self.epoch {
                    self.stamp[e] = self.epoch;
                    self.refresh(model, e, estimate);
                }
            }
        }
    }

    /// Recomputes every term (kills round-off drift of the running sum).
    pub fn recompute<P: EnginePose>(&mut self, model: &Model<P>, estimate: &[P]) {
        for (e, edge) in model.graph.edges().iter().enumerate() {
            self.per_edge[e] = if model.edges[e].applied {
                model.weight(e) * P::cached_chi2(&mut self.turns, &mut self.measured_turns, e, edge, estimate)
            } else {
                0.0
            };
        }
        self.total = self.per_edge.iter().sum();
    }
}
