//! [`Acks`]: which messages each frontend has had taken in, and which
//! repeat one already taken.
//!
//! A frontend numbers its messages 1, 2, 3, … across keyframes, edges and
//! fixes; the daemon drains the three queues one after another, so
//! numbers arrive out of order within a batch. A batch ends only when a
//! pass over the three finds them empty, so it holds every message a
//! frontend sent before the newest one in it. Per frontend the daemon
//! keeps `through`, the number up to which every message was taken, and
//! the numbers taken beyond it. The acknowledgement a snapshot carries is
//! `through`: a frontend may forget everything up to it. A message whose
//! number was taken already (a frontend resending after a daemon restart)
//! is a duplicate and is dropped.
//!
//! A frontend met for the first time may be one that talked to an earlier
//! daemon (without a state directory) and now sends again what that one
//! never acknowledged: its count starts at the lowest number of the first
//! batch it appears in, not at 1.

use crate::store::AckState;
use slamd_protocol::codec::Origin;
use slamd_protocol::{FrontendAck, MAX_FRONTENDS};
use std::collections::BTreeSet;
use std::time::{Duration, Instant};

/// Frontends remembered; beyond this the one quiet longest is forgotten.
const TRACKED: usize = 1024;

/// Numbers kept past a gap before the gap is given up as lost.
const MAX_BEYOND: usize = 1 << 16;

#[derive(Clone, Debug)]
struct Seen {
    frontend: u32,
    through: u64,
    beyond: BTreeSet<u64>,
    /// Until its first batch ends: the lowest number taken.
    floor: Option<u64>,
    /// When it was last heard from (restored ones: when restored).
    heard: Option<Instant>,
}

/// Per-frontend acknowledgements, the most recently active last.
#[derive(Clone, Debug, Default)]
pub struct Acks {
    seen: Vec<Seen>,
}

impl Acks {
    /// Restores saved acknowledgements.
    pub fn from_saved(saved: &[AckState]) -> Self {
        let seen = saved
            .iter()
            .map(|a| Seen {
                frontend: a.frontend,
                through: a.through,
                beyond: a.beyond.iter().copied().collect(),
                floor: None,
                heard: None,
            })
            .collect();
        Self { seen }
    }

    /// What a checkpoint keeps.
    pub fn saved(&self) -> Vec<AckState> {
        self.seen
            .iter()
            .map(|s| AckState {
                frontend: s.frontend,
                through: s.through,
                beyond: s.beyond.iter().copied().collect(),
            })
            .collect()
    }

    /// Records message `o`; false if it was taken before (a duplicate).
    /// Frontend 0 (a sender without an id) is never a duplicate. For a
    /// frontend never seen, the lowest number of its first batch starts
    /// its count: what it sent before went to another daemon.
    pub fn take(&mut self, o: Origin) -> bool {
        if o.frontend == 0 {
            return true;
        }
        let at = match self.seen.iter().rposition(|s| s.frontend == o.frontend) {
            Some(i) => i,
            None => {
                if self.seen.len() == TRACKED {
                    self.seen.remove(0);
                }
                self.seen.push(Seen {
                    frontend: o.frontend,
                    through: o.sequence.saturating_sub(1),
                    beyond: BTreeSet::new(),
                    floor: Some(o.sequence),
                    heard: None,
                });
                self.seen.len() - 1
            }
        };
        if at + 1 != self.seen.len() {
            let s = self.seen.remove(at);
            self.seen.push(s);
        }
        let s = self.seen.last_mut().expect("just pushed");
        s.heard = Some(Instant::now());
        if let Some(floor) = s.floor.filter(|&f| o.sequence < f) {
            // below the first batch's start so far: the count starts lower
            s.beyond.extend(floor..=s.through);
            s.through = o.sequence - 1;
            s.floor = Some(o.sequence);
        }
        if o.sequence <= s.through || !s.beyond.insert(o.sequence) {
            return false;
        }
        while s.beyond.first() == Some(&(s.through + 1)) {
            s.beyond.pop_first();
            s.through += 1;
        }
        if s.beyond.len() > MAX_BEYOND {
            let first = s.beyond.pop_first().unwrap_or(s.through + 1);
            tracing::warn!(
                frontend = s.frontend,
                missing = s.through + 1,
                "Messages never arrived; acknowledging past them."
            );
            s.through = first;
            while s.beyond.first() == Some(&(s.through + 1)) {
                s.beyond.pop_first();
                s.through += 1;
            }
        }
        true
    }

    /// Frontends heard from within `within`.
    pub fn active(&self, within: Duration) -> usize {
        (self.seen.iter().rev())
            .take_while(|s| s.heard.is_some_and(|t| t.elapsed() <= within))
            .count()
    }

    /// Ends every frontend's first batch.
    pub fn seal(&mut self) {
        for s in &mut self.seen {
            s.floor = None;
        }
    }

    /// The acknowledgements a snapshot header carries: the most recently
    /// active frontends' `through`.
    pub fn header(&self) -> [FrontendAck; MAX_FRONTENDS] {
        let mut out = [FrontendAck::default(); MAX_FRONTENDS];
        let recent = self.seen.iter().rev().take(MAX_FRONTENDS);
        for (slot, s) in out.iter_mut().zip(recent) {
            *slot = FrontendAck {
                frontend: s.frontend,
                reserved: 0,
                sequence: s.through,
            };
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn o(frontend: u32, sequence: u64) -> Origin {
        Origin { frontend, sequence }
    }

    fn through(a: &Acks, frontend: u32) -> Option<u64> {
        a.header()
            .iter()
            .find(|x| x.frontend == frontend)
            .map(|x| x.sequence)
    }

    #[test]
    fn out_of_order_numbers_are_acknowledged_once_the_gap_fills() {
        let mut a = Acks::default();
        assert!(a.take(o(5, 1)));
        // a keyframe drained before the edge sent ahead of it
        assert!(a.take(o(5, 3)));
        assert_eq!(through(&a, 5), Some(1));
        assert!(a.take(o(5, 2)));
        assert_eq!(through(&a, 5), Some(3));
    }

    #[test]
    fn a_resent_message_is_a_duplicate() {
        let mut a = Acks::default();
        for s in 1..=4 {
            assert!(a.take(o(9, s)));
        }
        assert!(a.take(o(9, 6)));
        assert!(!a.take(o(9, 2)) && !a.take(o(9, 6)));
        assert!(a.take(o(9, 5)));
        assert_eq!(through(&a, 9), Some(6));
        // saved and restored, the same numbers are duplicates
        let mut b = Acks::from_saved(&a.saved());
        assert!(!b.take(o(9, 6)) && b.take(o(9, 7)));
        assert!(a.take(o(0, 1)) && a.take(o(0, 1)), "no id, no duplicates");
    }

    #[test]
    fn a_new_frontend_starts_its_count_at_its_first_batch() {
        let mut a = Acks::default();
        // sent again after a restart: keyframes drained before edges
        assert!(a.take(o(3, 501)));
        assert!(a.take(o(3, 503)));
        assert!(a.take(o(3, 500)));
        assert!(!a.take(o(3, 501)));
        assert_eq!(through(&a, 3), Some(501));
        assert!(a.take(o(3, 502)));
        assert_eq!(through(&a, 3), Some(503));
        a.seal();
        // after its first batch, a lower number is a duplicate
        assert!(!a.take(o(3, 499)));
        assert!(a.take(o(3, 505)));
        assert_eq!(through(&a, 3), Some(503), "504 is missing");
    }

    #[test]
    fn the_header_lists_the_most_recently_active() {
        let mut a = Acks::default();
        for f in 1..=(MAX_FRONTENDS as u32 + 2) {
            a.take(o(f, 1));
        }
        a.take(o(1, 2));
        assert_eq!(through(&a, 1), Some(2));
        assert_eq!(through(&a, 2), None, "quiet longest");
    }
}
