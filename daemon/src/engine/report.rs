//! What the engine reports: [`UpdateReport`] per update, [`EngineStats`]
//! over its life, and [`FactorWork`], the work behind a snapshot counted
//! without a clock.

/// Entries of `L` a factor's update walks swept and its back-substitutions
/// read: the work behind a snapshot, measured without a clock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FactorWork {
    /// Swept by update walks (a column's rows, once per walk).
    pub walked: u64,
    /// Read by back-substitutions.
    pub solved: u64,
}

impl std::ops::Sub for FactorWork {
    type Output = FactorWork;
    fn sub(self, base: FactorWork) -> FactorWork {
        FactorWork {
            walked: self.walked.saturating_sub(base.walked),
            solved: self.solved.saturating_sub(base.solved),
        }
    }
}

impl std::ops::AddAssign for FactorWork {
    fn add_assign(&mut self, more: FactorWork) {
        self.walked += more.walked;
        self.solved += more.solved;
    }
}

/// What an [`Engine::update`](super::Engine::update) did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateReport {
    /// The snapshot version it produced.
    pub version: u64,
    /// Keyframes whose estimate moved.
    pub moved: usize,
    /// χ² of the new estimate.
    pub chi2: f64,
    /// True when a finished re-solve was swapped in.
    pub resolved: bool,
    /// Loop closure switches the outlier filter's judge decided or changed
    /// that this update took in.
    pub decided: usize,
}

/// Counters of the engine's work.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EngineStats {
    /// Re-solves swapped in.
    pub resolves: usize,
    /// Refreshes swapped in.
    pub refreshes: usize,
    /// Seconds spent in re-solves (on their thread).
    pub resolve_seconds: f64,
    /// Refactorisations forced by a failed downdate.
    pub recoveries: usize,
    /// Inline relinearisations (`relinearise_ratio`).
    pub relinearisations: usize,
    /// Inline refactorisations with a fresh ordering, while a re-solve
    /// held the background thread and the factor filled in.
    pub reorders: usize,
    /// Inline re-solves forced by the nonlinearity check.
    pub nonlinear_resolves: usize,
    /// Inline re-solves forced by a run of agreeing loop closures switched
    /// off on arrival ([`DriftRun`](crate::outliers::DriftRun)), the
    /// judge's as of its last decisions.
    pub drift_resolves: usize,
    /// Loop closures awaiting the judge's decision now.
    pub pending: usize,
    /// Entries of the Gauss–Newton factor now.
    pub factor_nnz: usize,
    /// What the updates and solves on this thread have swept of the
    /// Gauss–Newton factors so far (a re-solve's catch-up on its own
    /// thread not counted).
    pub work: FactorWork,
}
