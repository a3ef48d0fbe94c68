//! [`LevenbergMarquardtParams`]: when the polish stops and how it damps.

/// Tuning of [`LevenbergMarquardt`](super::LevenbergMarquardt).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LevenbergMarquardtParams {
    /// Iteration cap (accepted and rejected steps both count).
    pub max_iterations: usize,
    /// Stop when an accepted step lowers χ² by less than this fraction.
    pub relative_error_tol: f64,
    /// Stop when χ² falls below this.
    pub absolute_error_tol: f64,
    /// Stop when the largest step component falls below this.
    pub step_tol: f64,
    /// Initial damping λ, relative to the diagonal of H (Marquardt scaling).
    /// Small on purpose: pose-graph Hessians are so ill-conditioned that even
    /// λ = 1e-5 stalls the map-wide modes (City10000 needs 9 iterations
    /// instead of 4); a rejected step raises λ quickly.
    pub initial_lambda: f64,
}

impl Default for LevenbergMarquardtParams {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            relative_error_tol: 1e-9,
            absolute_error_tol: 1e-12,
            step_tol: 1e-10,
            initial_lambda: 1e-9,
        }
    }
}
