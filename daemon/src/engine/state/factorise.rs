//! A fresh factor for a [`State`]: its model's joined keyframes in a
//! fresh elimination order, every applied edge and GPS prior factorised
//! at a linearisation point.

use super::{Model, State};
use crate::engine::gauss_newton::GaussNewton;
use crate::engine::{EngineConfig, EnginePose};
use crate::sparse::ordering::amd_newest_last;
use crate::sparse::FactorError;

impl<P: EnginePose> State<P> {
    /// The fresh factor of `model` linearised at `lin`, its keyframes in a
    /// fresh elimination order (the second half of a
    /// [`rebuild`](crate::engine::rebuild::rebuild)).
    pub fn factorise(
        mut model: Model<P>,
        lin: Vec<P>,
        config: &EngineConfig,
    ) -> Result<State<P>, FactorError> {
        let recent = config.recent_last;
        let (joined, compact) = model.compact_joined();
        let active: Vec<(usize, f64)> = (0..model.graph.edges().len())
            .filter(|&e| model.edges[e].applied && model.weight(e) > 0.0)
            .map(|e| (e, model.weight(e)))
            .collect();
        // every fix on a joined keyframe enters the fresh factor
        let mut priors = Vec::new();
        for f in 0..model.fixes.len() {
            let on = model.joined(model.fixes[f].fix.keyframe);
            let prior = if on { model.prior(f) } else { None };
            model.fixes[f].applied = prior.is_some();
            priors.extend(prior);
        }
        // elimination order over joined keyframes except the gauge
        let pairs = active.iter().filter_map(|&(e, _)| {
            let edge = &model.graph.edges()[e];
            let (a, b) = (compact[edge.from], compact[edge.to]);
            (a > 0 && b > 0).then(|| (a - 1, b - 1))
        });
        let perm = amd_newest_last(joined.len().saturating_sub(1), pairs, recent);
        let order: Vec<usize> = perm.iter().map(|&c| joined[c + 1]).collect();
        let gn = GaussNewton::build(&model.graph, &active, &priors, lin, &order)?;
        let estimate = gn.estimate().to_vec();
        Ok(State::assemble(config, model, gn, estimate))
    }
}
