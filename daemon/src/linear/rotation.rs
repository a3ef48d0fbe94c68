//! Headings by 2-D registration (paper A §7).
//!
//! For keyframe `i`, the points `q_k` it knows in its own frame (each
//! neighbour's measured position, and its unit axes `1` and `i`) are matched
//! to the same points `p_k` in the solved map, relative to `p_i`. The
//! rotation minimising `Σ |e^{iθ} q_k − p_k|²` is Kabsch's answer, which in
//! the plane is `θ = arg Σ p_k q̄_k`.

use faer::c64;

/// The heading that best rotates `local` points onto `world` points.
pub fn register(pairs: impl IntoIterator<Item = (c64, c64)>) -> f64 {
    let s: c64 = pairs.into_iter().map(|(local, world)| world * local.conj()).sum();
    s.arg()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_rotation_despite_scale() {
        let rot = c64::from_polar(1.0, 2.5);
        let local = [c64::new(1.0, 0.0), c64::new(0.0, 1.0), c64::new(2.0, -1.0)];
        // world points are rotated and uniformly shrunk, as after a collapse
        let pairs = local.iter().map(|q| (*q, rot * q * 0.1));
        assert!((register(pairs) - 2.5).abs() < 1e-12);
    }
}
