//! [`WalkScratch`]: the working memory of the update walks. The factor
//! owns one and every walk reuses it, so that a walk allocates nothing once
//! the factor's size is reached; [`Paths`] are the walk's position in the
//! elimination tree.

/// Most vectors one call takes.
pub const MAX_RANK: usize = 12;

/// What an update walk works in, kept between walks: all of it is cleared
/// or overwritten before use, and the accumulators are left zero.
#[derive(Clone, Debug, Default)]
pub(super) struct WalkScratch<T> {
    /// Dense accumulators for the `w_t`, one vector per slot `t` (so that
    /// a run of rows is a slice), all zero between calls.
    pub(super) work: Vec<Vec<T>>,
    /// The merged rows of a column that gains rows among its own (swapped
    /// in as the column's).
    pub(super) rows: Vec<u32>,
    /// Their values.
    pub(super) vals: Vec<T>,
    /// The rows the paths joining at a column bring to it.
    pub(super) extra: Vec<u32>,
    /// Rows the last column of an update walk gained.
    pub(super) added: Vec<u32>,
    /// Which vector each live pivot of a column belongs to.
    pub(super) slots: [u8; MAX_RANK],
    /// The paths of the walk under way.
    pub(super) paths: Paths,
}

impl<T: Clone + Default> WalkScratch<T> {
    /// Scratch for a factor of `n` variables.
    pub(super) fn new(n: usize) -> Self {
        Self {
            work: vec![vec![T::default(); n]; MAX_RANK],
            rows: Vec::new(),
            vals: Vec::new(),
            extra: Vec::new(),
            added: Vec::new(),
            slots: [0; MAX_RANK],
            paths: Paths::default(),
        }
    }

    /// Room for one more variable.
    pub(super) fn append(&mut self) {
        self.work.iter_mut().for_each(|w| w.push(T::default()));
    }
}

/// The paths of one multiple-rank walk (Davis and Hager's multiple-rank
/// modification): each vector climbs the elimination tree from its first
/// nonzero; where paths reach the same column they join and go on as one.
/// Each holds the rows its next column must gain before its step.
#[derive(Clone, Debug, Default)]
pub(super) struct Paths {
    /// Next column of each slot; `usize::MAX` for a free slot.
    next: [usize; MAX_RANK],
    /// Rows to merge into that column (unsorted, may repeat).
    pending: [Vec<u32>; MAX_RANK],
}

impl Paths {
    /// Frees every slot.
    pub(super) fn clear(&mut self) {
        self.next = [usize::MAX; MAX_RANK];
    }

    /// The slot of a path at `column`, a new one if none is there; returns
    /// its pending rows.
    pub(super) fn start(&mut self, column: usize) -> &mut Vec<u32> {
        let slot = match self.next.iter().position(|&n| n == column) {
            Some(s) => s,
            None => {
                let s = self
                    .next
                    .iter()
                    .position(|&n| n == usize::MAX)
                    .expect("at most MAX_RANK vectors, one path each");
                self.next[s] = column;
                self.pending[s].clear();
                s
            }
        };
        &mut self.pending[slot]
    }

    /// The lowest column some path is at.
    pub(super) fn lowest(&self) -> Option<usize> {
        self.next.iter().copied().filter(|&n| n != usize::MAX).min()
    }

    /// Joins every path at `column` into the lowest such slot, appending
    /// their pending rows to `rows`; returns the slot.
    pub(super) fn join_at(&mut self, column: usize, rows: &mut Vec<u32>) -> usize {
        let mut slot = usize::MAX;
        for s in 0..MAX_RANK {
            if self.next[s] == column {
                rows.extend_from_slice(&self.pending[s]);
                if slot == usize::MAX {
                    slot = s;
                } else {
                    self.next[s] = usize::MAX;
                }
            }
        }
        slot
    }

    /// Moves `slot` on to `column`, which must gain `rows`.
    pub(super) fn advance(&mut self, slot: usize, column: usize, rows: &[u32]) {
        self.next[slot] = column;
        self.pending[slot].clear();
        self.pending[slot].extend_from_slice(rows);
    }

    /// Frees `slot`: its path left the tree at a root.
    pub(super) fn end(&mut self, slot: usize) {
        self.next[slot] = usize::MAX;
    }
}
