//! How a change of an edge's scale or switch applies to a [`State`]: the
//! checks, and the difference of its weight into the factor.

use super::{EdgeState, State};
use crate::engine::{EngineError, EnginePose};
use crate::graph::{Edge, EdgeKind};

impl<P: EnginePose> State<P> {
    /// Checks a reweight without applying it.
    pub fn check_weight(&self, edge: usize, scale: f64) -> Result<(), EngineError> {
        let e = self.edge(edge)?;
        if !scale.is_finite() || scale < 0.0 {
            return Err(EngineError::InvalidWeight(scale));
        }
        if e.kind == EdgeKind::Odometry && scale == 0.0 {
            return Err(EngineError::OdometrySwitch(edge));
        }
        Ok(())
    }

    /// Sets edge `e`'s scale, checked.
    pub(super) fn reweight(&mut self, e: usize, scale: f64) -> Result<(), EngineError> {
        self.check_weight(e, scale)?;
        self.change(e, |s| s.scale = scale)
    }

    /// Sets loop closure `e`'s switch as the judge decided.
    pub(super) fn set_switch(&mut self, e: usize, switch: f64) -> Result<(), EngineError> {
        self.check_switch(e, switch)?;
        self.change(e, |s| s.switch = switch)
    }

    /// Checks a switch: a switchable edge, a value in [0, 1].
    fn check_switch(&self, e: usize, switch: f64) -> Result<(), EngineError> {
        let edge = self.edge(e)?;
        if !edge.kind.switchable() || !(0.0..=1.0).contains(&switch) {
            return Err(EngineError::InvalidWeight(switch));
        }
        Ok(())
    }

    /// Sets many switches at once, leaving the factor behind for the
    /// caller to rebuild: the terms of edges in the factor are not
    /// updated (one refactorisation costs less than many updates into an
    /// ordering that did not foresee them). Invalid decisions are skipped.
    pub fn set_switches_for_rebuild(&mut self, decisions: &[(usize, f64)]) -> Result<(), EngineError> {
        let mut result = Ok(());
        for &(e, switch) in decisions {
            if let Err(err) = self.check_switch(e, switch) {
                result = Err(err);
                continue;
            }
            let state = &mut self.model.edges[e];
            if state.applied {
                state.switch = switch;
            } else if let Err(err) = self.set_switch(e, switch) {
                result = Err(err);
            }
        }
        result
    }

    /// Applies `set` to edge `e`'s state and the change of its weight to
    /// the factor; an edge that waited while it weighed nothing connects.
    fn change(&mut self, e: usize, set: impl FnOnce(&mut EdgeState)) -> Result<(), EngineError> {
        let before = self.model.weight(e);
        set(&mut self.model.edges[e]);
        let after = self.model.weight(e);
        if self.model.edges[e].applied {
            if after != before {
                self.contribute(e, after - before)?;
                self.refresh_edge(e);
            }
            Ok(())
        } else if after > 0.0 && !self.model.unconnected.contains(&e) {
            self.connect(e)
        } else {
            Ok(())
        }
    }

    /// Edge `e` of the graph, or [`EngineError::UnknownEdge`].
    fn edge(&self, e: usize) -> Result<&Edge<P>, EngineError> {
        self.model.graph.edges().get(e).ok_or(EngineError::UnknownEdge(e))
    }
}
