//! [`Kernel`]: the closed-form switch of a loop closure and the robust cost
//! it implies.
//!
//! Switchable constraints minimise `s² χ² + Ξ (1 − s)²` per loop closure;
//! setting the derivative in `s` to zero gives the switch in closed form,
//! so only poses are optimised and `s²` is an iteratively reweighted least
//! squares weight on the edge's `Ω` (docs/design.md, "Robust kernels and
//! switches"). Each kernel gives the switch `s(χ²)` and the cost `ρ(χ²)`
//! whose derivative is `s²`, which is what the polish compares when it
//! accepts a step.

/// How a loop closure's switch follows its error.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Kernel {
    /// Switchable constraints with a fixed prior weight Ξ:
    /// `s = Ξ / (Ξ + χ²)`, `ρ = Ξ χ² / (Ξ + χ²)` (Geman–McClure).
    /// `Ξ = 1` is the unit-free reading of paper B that works.
    Sc {
        /// The prior weight Ξ.
        xi: f64,
    },
    /// Dynamic covariance scaling: `s = min(1, 2Φ / (Φ + χ²))`,
    /// `ρ = χ²` below Φ and `Φ (3χ² − Φ) / (Φ + χ²)` above.
    Dcs {
        /// The threshold Φ.
        phi: f64,
    },
    /// Paper B's adaptive switch as printed: `s = 1 / (χ² χ′ |Λ| + 1)`,
    /// with `χ′` the squared Euclidean error and `|Λ|` the determinant of
    /// the loop closure's covariance; that is SC with `Ξ = 1 / (χ′ |Λ|)`.
    /// Its `χ′ |Λ|` carries units (m⁴·rad²…), so it depends on the dataset's
    /// scale; kept for measurement.
    Asc,
}

/// DCS's default Φ. A switch falls below 0.5 once `χ² > 3Φ`; at
/// `Φ = 16.27 / 3` that is the 99.9% quantile of χ² with 3 degrees of
/// freedom, so a loop closure whose information is right is held wrong
/// once in a thousand (Φ = 1 rejects 46 of 150 true loop closures of the
/// calibrated synthetic world).
pub const DEFAULT_PHI: f64 = 16.27 / 3.0;

/// DCS's default Φ for a 3-D edge: the same rule at six degrees of
/// freedom, `χ²₆(0.999) / 3 = 22.458 / 3`.
pub const DEFAULT_PHI_6DOF: f64 = 22.458 / 3.0;

impl Kernel {
    /// The default kernel for edges of `dof` degrees of freedom (DCS with
    /// [`DEFAULT_PHI`] or [`DEFAULT_PHI_6DOF`]).
    pub fn default_for(dof: usize) -> Self {
        match dof {
            6 => Kernel::Dcs {
                phi: DEFAULT_PHI_6DOF,
            },
            _ => Kernel::default(),
        }
    }
}

impl Default for Kernel {
    fn default() -> Self {
        Kernel::Dcs { phi: DEFAULT_PHI }
    }
}

impl Kernel {
    /// Checks the parameter: Φ and Ξ must be finite and > 0.
    pub fn check(&self) -> Result<(), String> {
        match *self {
            Kernel::Dcs { phi: v } | Kernel::Sc { xi: v } if !(v.is_finite() && v > 0.0) => {
                Err(format!("the kernel's parameter {v} must be a number > 0"))
            }
            _ => Ok(()),
        }
    }

    /// The switch `s ∈ [0, 1]` of an edge whose error has `χ² = eᵀ Ω e`;
    /// `asc` gives paper B's `χ′ |Λ|` of the edge (the squared Euclidean
    /// error times the determinant of its covariance), asked only by
    /// [`Kernel::Asc`].
    pub fn switch(&self, chi2: f64, asc: impl FnOnce() -> f64) -> f64 {
        match *self {
            Kernel::Sc { xi } => sc(chi2, xi),
            Kernel::Dcs { phi } => dcs(chi2, phi),
            Kernel::Asc => 1.0 / (chi2 * asc() + 1.0),
        }
    }

    /// The robust cost `ρ(χ²)` of an edge whose error has `χ² = eᵀ Ω e`;
    /// `asc` as for [`Self::switch`].
    pub fn cost(&self, chi2: f64, asc: impl FnOnce() -> f64) -> f64 {
        match *self {
            Kernel::Sc { xi } => xi * chi2 / (xi + chi2),
            Kernel::Dcs { phi } if chi2 <= phi => chi2,
            Kernel::Dcs { phi } => phi * (3.0 * chi2 - phi) / (phi + chi2),
            Kernel::Asc => {
                let w = 1.0 / asc().max(f64::MIN_POSITIVE);
                w * chi2 / (w + chi2)
            }
        }
    }
}

/// SC's switch `Ξ / (Ξ + χ²)`.
pub fn sc(chi2: f64, xi: f64) -> f64 {
    xi / (xi + chi2)
}

/// DCS's switch `min(1, 2Φ / (Φ + χ²))`.
pub fn dcs(chi2: f64, phi: f64) -> f64 {
    (2.0 * phi / (phi + chi2)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No χ′ |Λ|: the kernels other than ASC never ask.
    fn unasked() -> f64 {
        unreachable!("only ASC asks for χ′ |Λ|")
    }

    #[test]
    fn closed_forms_match_hand_computed_values() {
        // χ² = 8 (the error (0, 2, 0) under Ω = diag(1, 2, 4))
        assert!((Kernel::Sc { xi: 1.0 }.switch(8.0, unasked) - 1.0 / 9.0).abs() < 1e-15);
        assert!((Kernel::Sc { xi: 1.0 }.cost(8.0, unasked) - 8.0 / 9.0).abs() < 1e-15);
        assert!((Kernel::Dcs { phi: 1.0 }.switch(8.0, unasked) - 2.0 / 9.0).abs() < 1e-15);
        assert!((Kernel::Dcs { phi: 1.0 }.cost(8.0, unasked) - 23.0 / 9.0).abs() < 1e-15);
        // ASC with χ′ |Λ| = 1/2: s = 1/(8·1/2 + 1) = 1/5, ρ = 2·8/(2 + 8)
        assert!((Kernel::Asc.switch(8.0, || 0.5) - 0.2).abs() < 1e-15);
        assert!((Kernel::Asc.cost(8.0, || 0.5) - 1.6).abs() < 1e-15);
        // below Φ, DCS leaves the edge alone (the error (0, 0.1, 0): χ² 0.02)
        assert_eq!(Kernel::Dcs { phi: 1.0 }.switch(0.02, unasked), 1.0);
        assert!((Kernel::Dcs { phi: 1.0 }.cost(0.02, unasked) - 0.02).abs() < 1e-15);
    }

    #[test]
    fn the_cost_derivative_is_the_squared_switch() {
        // dρ/dχ² = s²: check by finite differences on χ²
        let h = 1e-6;
        for chi2 in [0.3, 0.99, 1.5, 7.0, 300.0] {
            let rho_sc = |c: f64| 2.0 * c / (2.0 + c);
            let d = (rho_sc(chi2 + h) - rho_sc(chi2 - h)) / (2.0 * h);
            assert!((d - sc(chi2, 2.0).powi(2)).abs() < 1e-6, "sc at {chi2}");
            let rho_dcs = |c: f64| if c <= 1.0 { c } else { (3.0 * c - 1.0) / (1.0 + c) };
            let d = (rho_dcs(chi2 + h) - rho_dcs(chi2 - h)) / (2.0 * h);
            assert!((d - dcs(chi2, 1.0).powi(2)).abs() < 1e-6, "dcs at {chi2}");
        }
    }
}
