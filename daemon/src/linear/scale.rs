//! Paper A's global scale ρ, in closed form.
//!
//! All virtual-frame equations are homogeneous, so every coordinate solved
//! with the gauge axis of length 1 is ρ times the coordinate for a gauge of
//! length ρ. The paper picks ρ to minimise
//! `J(ρ) = Σ_k (ρ² a_k − c_k)²`, where `a_k` are squared lengths at ρ = 1
//! (the two virtual axes of every keyframe, with target `c_k = 1`, and every
//! edge `|p_i − p_j|²`, with target `|t_ij|²`). `J` is a quadratic in ρ², so
//! `ρ² = Σ a_k c_k / Σ a_k²`.

/// The minimiser ρ ≥ 0 of `Σ (ρ² a_k − c_k)²` over `(a_k, c_k)` pairs.
pub fn closed_form_scale(pairs: impl IntoIterator<Item = (f64, f64)>) -> f64 {
    let (num, den) = pairs
        .into_iter()
        .fold((0.0, 0.0), |(n, d), (a, c)| (n + a * c, d + a * a));
    if den > 0.0 {
        (num / den).max(0.0).sqrt()
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_scale() {
        // Lengths shrunk by 1/2 (squared: 1/4) need ρ = 2.
        let pairs = [(0.25, 1.0), (1.0, 4.0), (0.5625, 2.25)];
        assert!((closed_form_scale(pairs) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn matches_a_brute_force_minimum() {
        let pairs = [(0.3, 1.0), (0.5, 1.0), (2.0, 9.0), (1.1, 3.0)];
        let j = |r: f64| pairs.iter().map(|(a, c)| (r * r * a - c).powi(2)).sum::<f64>();
        let rho = closed_form_scale(pairs);
        for k in 1..400 {
            let r = k as f64 * 0.01;
            assert!(j(rho) <= j(r) + 1e-12, "J({rho}) > J({r})");
        }
    }
}
