//! Planar rigid motions: [`Pose2`] and angle wrapping (from
//! [`slamd_types`]), and a cache of rotations for the χ² bookkeeping.

pub use slamd_types::{wrap_angle, Pose2};

use num_complex::Complex64;

/// Rotations `e^{iθ}` remembered per slot with the heading they were
/// computed for: [`Self::get`] recomputes only when the heading changed,
/// so a cache that misses an update can never answer stale.
#[derive(Clone, Debug, Default)]
pub struct Turns {
    /// Heading and its rotation, side by side (one cache line a lookup).
    slots: Vec<(f64, Complex64)>,
}

impl Turns {
    /// `e^{iθ}` for slot `k` at heading `theta`.
    pub fn get(&mut self, k: usize, theta: f64) -> Complex64 {
        if k >= self.slots.len() {
            self.slots.resize(k + 1, (f64::NAN, Complex64::new(1.0, 0.0)));
        }
        let slot = &mut self.slots[k];
        // a NaN heading never equals itself: computed every time
        if slot.0 != theta {
            *slot = (theta, Complex64::from_polar(1.0, theta));
        }
        slot.1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turns_follow_the_heading_they_are_asked_for() {
        let mut turns = Turns::default();
        assert_eq!(turns.get(3, 0.5), Pose2::new(0.0, 0.0, 0.5).rotation());
        assert_eq!(turns.get(3, -1.25), Pose2::new(0.0, 0.0, -1.25).rotation());
        assert_eq!(turns.get(0, 2.0), Pose2::new(0.0, 0.0, 2.0).rotation());
        assert_eq!(turns.get(3, -1.25), Pose2::new(0.0, 0.0, -1.25).rotation());
        assert!(turns.get(1, f64::NAN).re.is_nan());
    }
}
