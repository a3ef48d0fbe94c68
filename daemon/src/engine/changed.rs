//! [`Changed`]: which keyframes' estimates changed since a snapshot last
//! asked, so that a snapshot can carry only those.

/// What changed since the engine was last asked
/// ([`Engine::take_changes`](super::Engine::take_changes)).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Changes {
    /// Possibly every keyframe: the estimate was replaced (a re-solve or a
    /// refresh swapped in, a rebuild, a restart).
    All,
    /// These keyframes (indices in arrival order, each once, ascending).
    Some(Vec<usize>),
}

/// Keyframes whose estimate changed: marked by the solve that moved them
/// or the join that placed them, taken by the snapshot.
#[derive(Clone, Debug)]
pub struct Changed {
    all: bool,
    list: Vec<usize>,
    marked: Vec<bool>,
}

impl Default for Changed {
    /// Everything changed: nothing was taken yet.
    fn default() -> Self {
        Self {
            all: true,
            list: Vec::new(),
            marked: Vec::new(),
        }
    }
}

impl Changed {
    /// Keyframe `k`'s estimate changed.
    pub fn mark(&mut self, k: usize) {
        if self.all {
            return;
        }
        if k >= self.marked.len() {
            self.marked.resize(k + 1, false);
        }
        if !self.marked[k] {
            self.marked[k] = true;
            self.list.push(k);
        }
    }

    /// Every estimate may have changed.
    pub fn mark_all(&mut self) {
        self.all = true;
        self.clear();
    }

    /// What changed since the last call; marks start over.
    pub fn take(&mut self) -> Changes {
        if std::mem::take(&mut self.all) {
            return Changes::All;
        }
        let mut list = std::mem::take(&mut self.list);
        list.sort_unstable();
        for &k in &list {
            self.marked[k] = false;
        }
        Changes::Some(list)
    }

    fn clear(&mut self) {
        for &k in &self.list {
            self.marked[k] = false;
        }
        self.list.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_are_taken_once_each_in_order_and_all_overrides_them() {
        let mut c = Changed::default();
        assert_eq!(c.take(), Changes::All);
        assert_eq!(c.take(), Changes::Some(vec![]));
        for k in [9, 2, 9, 4] {
            c.mark(k);
        }
        assert_eq!(c.take(), Changes::Some(vec![2, 4, 9]));
        c.mark(3);
        c.mark_all();
        c.mark(5);
        assert_eq!(c.take(), Changes::All);
        c.mark(3);
        assert_eq!(c.take(), Changes::Some(vec![3]));
    }
}
