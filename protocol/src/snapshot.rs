//! [`MapSnapshot`] and [`Assembly`]: a subscriber's copy of the map, put
//! together from whole snapshots (`{ns}/poses`) and the changes between
//! them (`{ns}/changes`).
//!
//! The daemon publishes every snapshot version on `{ns}/changes`: the poses
//! that changed since the version before (`base`), or, when the map
//! changed too much or too long ago went out whole, an empty sample with
//! `whole` 1 whose map is on `{ns}/poses`. A subscriber holding version
//! `v` of daemon start `i` takes the change whose base is `v`; a whole map
//! of another start, or of a newer version, replaces what it holds. A
//! change it cannot place yet (its base is newer: an older one was lost to
//! a full queue) waits for a whole map to catch up from; the daemon sends
//! one at least every `snapshot.full_every_ms`.

use crate::message::{Pose, SnapshotHeader};
use std::collections::{BTreeMap, HashMap};

/// Changes kept while waiting for a whole map to place them on; beyond
/// this the oldest are dropped (they could only be placed on a whole map
/// older than ones already lost).
const MAX_WAITING: usize = 4096;

/// One version of the whole map: its header (`poses` is the map's size,
/// `whole` 1, `base` 0) and every pose, keyed by keyframe id.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapSnapshot {
    header: SnapshotHeader,
    poses: Vec<Pose>,
    index: HashMap<u64, usize>,
}

impl MapSnapshot {
    /// The header of the newest version taken in.
    pub fn header(&self) -> &SnapshotHeader {
        &self.header
    }

    /// Every pose: in the daemon's keyframe order after a whole map, with
    /// keyframes that joined since appended.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// The pose of keyframe `id`, if it is in the map.
    pub fn pose(&self, id: u64) -> Option<&Pose> {
        self.index.get(&id).map(|&i| &self.poses[i])
    }

    fn whole(header: &SnapshotHeader, poses: &[Pose]) -> Self {
        let mut s = Self {
            header: *header,
            poses: poses.to_vec(),
            index: HashMap::with_capacity(poses.len()),
        };
        for (i, p) in s.poses.iter().enumerate() {
            s.index.insert(p.id, i);
        }
        s.seal();
        s
    }

    /// Takes in one version's changed poses and header.
    fn change(&mut self, header: &SnapshotHeader, poses: &[Pose]) {
        for p in poses {
            match self.index.get(&p.id) {
                Some(&i) => self.poses[i] = *p,
                None => {
                    self.index.insert(p.id, self.poses.len());
                    self.poses.push(*p);
                }
            }
        }
        self.header = *header;
        self.seal();
    }

    /// The header then describes the whole map held.
    fn seal(&mut self) {
        self.header.poses = self.poses.len() as u64;
        self.header.whole = 1;
        self.header.base = 0;
    }

    fn holds(&self, header: &SnapshotHeader) -> bool {
        self.header.instance == header.instance && header.version <= self.header.version
    }
}

/// A change that came before the map it changes.
#[derive(Clone, Debug)]
struct Waiting {
    header: SnapshotHeader,
    poses: Vec<Pose>,
}

/// The subscriber's side of the protocol above: takes whole maps and
/// changes in any order and keeps the newest map it can build.
#[derive(Clone, Debug, Default)]
pub struct Assembly {
    current: Option<MapSnapshot>,
    /// Changes not yet placed, by (daemon start, base version).
    waiting: BTreeMap<(u64, u64), Waiting>,
    advanced: bool,
}

impl Assembly {
    /// The newest map built, if any.
    pub fn current(&self) -> Option<&MapSnapshot> {
        self.current.as_ref()
    }

    /// Takes a whole map from `{ns}/poses`.
    pub fn whole(&mut self, header: &SnapshotHeader, poses: &[Pose]) {
        if self.current.as_ref().is_some_and(|c| c.holds(header)) {
            return;
        }
        self.current = Some(MapSnapshot::whole(header, poses));
        let (instance, version) = (header.instance, header.version);
        self.waiting
            .retain(|&(i, base), _| i == instance && base >= version);
        self.advanced = true;
        self.place();
    }

    /// Takes a sample from `{ns}/changes`.
    pub fn change(&mut self, header: &SnapshotHeader, poses: &[Pose]) {
        if self.current.as_ref().is_some_and(|c| c.holds(header)) {
            return;
        }
        let waiting = Waiting {
            header: *header,
            poses: poses.to_vec(),
        };
        self.waiting.insert((header.instance, header.base), waiting);
        while self.waiting.len() > MAX_WAITING {
            self.waiting.pop_first();
        }
        self.place();
    }

    /// Whether the map moved on to a newer version since the last call.
    pub fn take_advanced(&mut self) -> bool {
        std::mem::take(&mut self.advanced)
    }

    /// Applies every waiting change that follows the map held, in order.
    fn place(&mut self) {
        let Some(current) = self.current.as_mut() else {
            return;
        };
        loop {
            let key = (current.header.instance, current.header.version);
            // a whole version's map comes on `{ns}/poses`, not here
            match self.waiting.get(&key) {
                Some(w) if w.header.whole == 0 => {}
                _ => break,
            }
            let w = self.waiting.remove(&key).expect("looked up");
            current.change(&w.header, &w.poses);
            self.advanced = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(instance: u64, version: u64, base: u64, whole: bool) -> SnapshotHeader {
        SnapshotHeader {
            instance,
            version,
            base,
            whole: u32::from(whole),
            chi2: version as f64,
            ..SnapshotHeader::default()
        }
    }

    fn pose(id: u64, x: f64) -> Pose {
        Pose {
            id,
            x,
            ..Pose::default()
        }
    }

    fn xs(a: &Assembly) -> Vec<(u64, f64)> {
        let s = a.current().expect("a map");
        s.poses().iter().map(|p| (p.id, p.x)).collect()
    }

    #[test]
    fn changes_after_a_whole_map_update_it_in_order() {
        let mut a = Assembly::default();
        assert!(a.current().is_none());
        a.whole(&header(7, 3, 0, true), &[pose(1, 0.0), pose(2, 1.0)]);
        assert!(a.take_advanced());
        a.change(&header(7, 4, 3, false), &[pose(2, 1.5), pose(3, 2.0)]);
        a.change(&header(7, 5, 4, false), &[pose(1, 0.1)]);
        assert!(a.take_advanced());
        assert_eq!(xs(&a), [(1, 0.1), (2, 1.5), (3, 2.0)]);
        let h = a.current().unwrap().header();
        assert_eq!((h.version, h.poses, h.whole, h.base, h.chi2), (5, 3, 1, 0, 5.0));
        assert_eq!(a.current().unwrap().pose(3).map(|p| p.x), Some(2.0));
        assert!(!a.take_advanced());
    }

    #[test]
    fn a_change_that_came_first_waits_for_its_map() {
        let mut a = Assembly::default();
        // the whole map of version 3 is read after the changes of 4 and 5
        a.change(&header(7, 5, 4, false), &[pose(1, 5.0)]);
        a.change(&header(7, 4, 3, false), &[pose(2, 4.0)]);
        assert!(a.current().is_none());
        a.whole(&header(7, 3, 0, true), &[pose(1, 0.0), pose(2, 0.0)]);
        assert_eq!(xs(&a), [(1, 5.0), (2, 4.0)]);
        assert_eq!(a.current().unwrap().header().version, 5);
    }

    #[test]
    fn a_lost_change_stops_the_map_until_the_next_whole_one() {
        let mut a = Assembly::default();
        a.whole(&header(7, 3, 0, true), &[pose(1, 0.0)]);
        a.take_advanced();
        // version 4 was lost to a full queue
        a.change(&header(7, 5, 4, false), &[pose(1, 5.0)]);
        a.change(&header(7, 6, 5, false), &[pose(1, 6.0)]);
        assert!(!a.take_advanced());
        assert_eq!(a.current().unwrap().header().version, 3);
        // a version published whole: its marker is not a change to place
        a.change(&header(7, 7, 6, true), &[]);
        a.whole(&header(7, 7, 0, true), &[pose(1, 7.0), pose(2, 7.0)]);
        a.change(&header(7, 8, 7, false), &[pose(2, 8.0)]);
        assert!(a.take_advanced());
        assert_eq!(xs(&a), [(1, 7.0), (2, 8.0)]);
        // what waited below the whole map is gone
        assert!(a.waiting.is_empty());
    }

    #[test]
    fn an_older_whole_map_is_ignored_and_a_restarted_daemon_replaces_the_map() {
        let mut a = Assembly::default();
        a.whole(&header(7, 3, 0, true), &[pose(1, 0.0)]);
        a.change(&header(7, 4, 3, false), &[pose(1, 4.0)]);
        a.whole(&header(7, 3, 0, true), &[pose(1, 0.0)]);
        a.change(&header(7, 4, 3, false), &[pose(1, 99.0)]);
        assert_eq!(xs(&a), [(1, 4.0)]);
        // a restart counts versions again under a new instance
        a.change(&header(8, 2, 1, false), &[pose(1, 2.0)]);
        assert_eq!(a.current().unwrap().header().version, 4);
        a.whole(&header(8, 1, 0, true), &[pose(1, 1.0)]);
        assert_eq!(xs(&a), [(1, 2.0)]);
        assert_eq!(a.current().unwrap().header().instance, 8);
    }
}
