//! [`Held`]: edges and GPS fixes waiting for a keyframe that has not
//! arrived yet.
//!
//! Frontends publish on independent queues, so an edge or a fix can
//! overtake its keyframe. It waits here, keyed by the missing id, until the
//! keyframe arrives, the wait exceeds a timeout, or the buffer is full.

use crate::graph::KeyframeId;
use slamd_protocol::codec::Origin;
use std::collections::HashMap;
use std::time::{Duration, Instant};

/// One waiting message.
#[derive(Clone, Copy, Debug)]
pub struct Waiting<T> {
    /// Who sent it.
    pub origin: Origin,
    /// The edge or fix.
    pub item: T,
    /// When it started waiting.
    pub since: Instant,
}

/// Messages by the keyframe they wait for, with a cap on the total.
#[derive(Debug)]
pub struct Held<T> {
    by_missing: HashMap<KeyframeId, Vec<Waiting<T>>>,
    count: usize,
}

impl<T> Default for Held<T> {
    fn default() -> Self {
        Self {
            by_missing: HashMap::new(),
            count: 0,
        }
    }
}

impl<T: Copy> Held<T> {
    /// Number of waiting messages.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Parks `w` until `missing` arrives; false (and nothing stored) when
    /// `cap` are already waiting.
    pub fn hold(&mut self, missing: KeyframeId, w: Waiting<T>, cap: usize) -> bool {
        if self.count >= cap {
            return false;
        }
        self.by_missing.entry(missing).or_default().push(w);
        self.count += 1;
        true
    }

    /// The messages waiting for keyframe `id`.
    pub fn release(&mut self, id: KeyframeId) -> Vec<Waiting<T>> {
        let out = self.by_missing.remove(&id).unwrap_or_default();
        self.count -= out.len();
        out
    }

    /// Every waiting message, in no particular order.
    pub fn waiting(&self) -> impl Iterator<Item = &Waiting<T>> {
        self.by_missing.values().flatten()
    }

    /// Removes and returns the messages that have waited longer than
    /// `limit`, with the id each waited for.
    pub fn expire(&mut self, now: Instant, limit: Duration) -> Vec<(KeyframeId, Waiting<T>)> {
        let mut out = Vec::new();
        self.by_missing.retain(|&id, list| {
            list.retain(|h| {
                let old = now.duration_since(h.since) > limit;
                if old {
                    out.push((id, *h));
                }
                !old
            });
            !list.is_empty()
        });
        self.count -= out.len();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::EdgeInput;
    use crate::geometry::Pose2;
    use crate::graph::{EdgeKind, Information};

    fn held(at: Instant) -> Waiting<EdgeInput> {
        Waiting {
            origin: Origin {
                frontend: 1,
                sequence: 1,
            },
            item: EdgeInput::new(1, 2, Pose2::IDENTITY, Information::identity(), EdgeKind::Odometry),
            since: at,
        }
    }

    #[test]
    fn holds_releases_expires_and_caps() {
        let t0 = Instant::now();
        let mut h = Held::default();
        assert!(h.hold(2, held(t0), 2));
        assert!(h.hold(3, held(t0 + Duration::from_secs(10)), 2));
        assert!(!h.hold(4, held(t0), 2), "cap of 2");
        assert_eq!(h.release(2).len(), 1);
        assert_eq!(h.len(), 1);
        assert!(h
            .expire(t0 + Duration::from_secs(12), Duration::from_secs(5))
            .is_empty());
        let gone = h.expire(t0 + Duration::from_secs(16), Duration::from_secs(5));
        assert_eq!((gone.len(), gone[0].0, h.len()), (1, 3, 0));
    }
}
