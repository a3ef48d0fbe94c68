//! [`Publication`]: whether a snapshot goes out whole or as the poses it
//! changed.
//!
//! A keyframe far from any loop closure moves a handful of poses (the new
//! one and those the back-substitution reaches), so a snapshot carries
//! those on `{ns}/changes` and costs the same at a million keyframes as at
//! ten thousand. The whole map goes out on `{ns}/poses` when the estimate
//! was replaced (a re-solve or refresh swapped in), when more than
//! `ipc.max_changes` poses changed, when the georeference changed (every
//! ENU pose moves with it), after a failed send (a subscriber would miss
//! the changes it lost), with the settled map (a reader that only takes
//! whole maps gets the final one), and at least every
//! `snapshot.whole_every_ms`, so a late subscriber or one whose queue
//! overflowed has a map to start from.

use crate::engine::Changes;
use crate::gps::Georef;
use std::time::{Duration, Instant};

/// What the next snapshot carries.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) enum Carry {
    /// The whole map.
    Whole,
    /// The changes since version `base`: these keyframes (indices in
    /// arrival order).
    Changes { base: u64, keyframes: Vec<usize> },
}

/// The state of the decision between snapshots, and what went out.
#[derive(Clone, Debug)]
pub(super) struct Publication {
    max_changes: usize,
    whole_every: Duration,
    /// The version last published, unless the next must go out whole.
    base: Option<u64>,
    last_whole: Option<Instant>,
    georef: Option<Georef>,
    /// Which keyframes (by index) the published map holds, and how many.
    held: Vec<bool>,
    size: usize,
    /// Snapshots published, and of them whole ones.
    pub published: u64,
    pub whole: u64,
    /// Poses published, whole and as changes.
    pub poses: u64,
}

impl Publication {
    /// Changes of at most `max_changes` poses, the whole map at least every
    /// `whole_every`.
    pub fn new(max_changes: usize, whole_every: Duration) -> Self {
        Self {
            max_changes,
            whole_every,
            base: None,
            last_whole: None,
            georef: None,
            held: Vec::new(),
            size: 0,
            published: 0,
            whole: 0,
            poses: 0,
        }
    }

    /// What the snapshot of `version` carries, given what changed since the
    /// last one and its georeference, at `now`.
    pub fn plan(&mut self, version: u64, changes: Changes, georef: Option<Georef>, now: Instant) -> Carry {
        let due = self
            .last_whole
            .is_none_or(|t| now.duration_since(t) >= self.whole_every);
        let moved_frame = std::mem::replace(&mut self.georef, georef) != georef;
        let carry = match (self.base.take(), changes) {
            (Some(base), Changes::Some(keyframes))
                if !due && !moved_frame && keyframes.len() <= self.max_changes =>
            {
                Carry::Changes { base, keyframes }
            }
            _ => Carry::Whole,
        };
        if carry == Carry::Whole {
            self.last_whole = Some(now);
        }
        self.base = Some(version);
        carry
    }

    /// The snapshot just planned went out whole: whether each keyframe
    /// (by index) is in the map.
    pub fn sent_whole(&mut self, joined: impl Iterator<Item = bool>) {
        self.held.clear();
        self.held.extend(joined);
        self.size = self.held.iter().filter(|&&j| j).count();
        self.published += 1;
        self.whole += 1;
        self.poses += self.size as u64;
    }

    /// The snapshot just planned went out as the changes of these
    /// keyframes, each in the map.
    pub fn sent_changes(&mut self, keyframes: &[usize]) {
        for &k in keyframes {
            if k >= self.held.len() {
                self.held.resize(k + 1, false);
            }
            self.size += usize::from(!std::mem::replace(&mut self.held[k], true));
        }
        self.published += 1;
        self.poses += keyframes.len() as u64;
    }

    /// The next snapshot goes out whole (the one just planned could not be
    /// sent, or the next is the settled map).
    pub fn whole_next(&mut self) {
        self.base = None;
    }

    /// Keyframes in the published map.
    pub fn map_size(&self) -> usize {
        self.size
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn some(k: &[usize]) -> Changes {
        Changes::Some(k.to_vec())
    }

    #[test]
    fn changes_go_out_between_whole_maps() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut p = Publication::new(3, Duration::from_millis(1000));
        // the first snapshot is whole, whatever changed
        assert_eq!(p.plan(1, some(&[0]), None, ms(0)), Carry::Whole);
        let changes = |base, k: &[usize]| Carry::Changes {
            base,
            keyframes: k.to_vec(),
        };
        assert_eq!(p.plan(2, some(&[1]), None, ms(1)), changes(1, &[1]));
        // versions not published do not matter: the base is the last sent
        assert_eq!(p.plan(5, some(&[1, 2, 3]), None, ms(2)), changes(2, &[1, 2, 3]));
        // too many, everything, a new georeference, a second gone by
        assert_eq!(p.plan(6, some(&[1, 2, 3, 4]), None, ms(3)), Carry::Whole);
        assert_eq!(p.plan(7, Changes::All, None, ms(4)), Carry::Whole);
        let g = Some(Georef {
            rotation: faer::c64::new(0.0, 1.0),
            translation: faer::c64::new(5.0, 0.0),
            up: 0.0,
        });
        assert_eq!(p.plan(8, some(&[1]), g, ms(5)), Carry::Whole);
        assert_eq!(p.plan(9, some(&[1]), g, ms(6)), changes(8, &[1]));
        assert_eq!(p.plan(10, some(&[1]), g, ms(1005)), Carry::Whole);
        // a failed send: the next goes out whole
        assert_eq!(p.plan(11, some(&[1]), g, ms(1006)), changes(10, &[1]));
        p.whole_next();
        assert_eq!(p.plan(12, some(&[1]), g, ms(1007)), Carry::Whole);
    }

    #[test]
    fn the_map_size_follows_whole_maps_and_new_keyframes() {
        let mut p = Publication::new(8, Duration::from_secs(1));
        p.sent_whole([true, false, true].into_iter());
        assert_eq!(p.map_size(), 2);
        // keyframe 1 joins, 2 moves, 4 is new
        p.sent_changes(&[1, 2, 4]);
        assert_eq!(p.map_size(), 4);
        p.sent_changes(&[4]);
        assert_eq!(p.map_size(), 4);
        assert_eq!((p.published, p.whole, p.poses), (3, 1, 6));
    }
}
