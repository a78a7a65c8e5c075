//! LRU cache of kernel-matrix rows for the SMO solver ([`super::smo`]): libsvm's
//! `Cache` (Chang & Lin 2011, §5.1). A row may be cached only up to a prefix
//! length (the solver's active set after shrinking); [`RowCache::swap_index`]
//! follows the solver's permutations. Rows are `f32`, as libsvm's `Qfloat`,
//! which doubles the rows that fit; gradients stay `f64`.

/// Sentinel slot of the doubly linked LRU list.
const NIL: usize = usize::MAX;

/// Rows of an `l × l` matrix, cached by LRU within a budget of `f32` entries.
#[derive(Debug)]
pub struct RowCache {
    /// Cached prefix of each row (empty when not cached).
    rows: Vec<Vec<f32>>,
    /// LRU links: `prev[i]`, `next[i]` for cached rows; `l` is the list head.
    prev: Vec<usize>,
    next: Vec<usize>,
    /// Entries still free in the budget.
    free: usize,
    /// A few evicted buffers kept for reuse: a fresh allocation per row would
    /// have the kernel zero new pages each time (beyond the budget by ≤ 2 rows).
    spare: Vec<Vec<f32>>,
}

impl RowCache {
    /// A cache for `l` rows with `budget_mb` MiB, never less than two full rows
    /// (the solver holds two rows at once, so neither may evict the other).
    pub fn new(l: usize, budget_mb: f64) -> Self {
        let entries = (budget_mb.max(0.0) * (1u64 << 20) as f64 / 4.0) as usize;
        let head = l;
        let mut prev = vec![NIL; l + 1];
        let mut next = vec![NIL; l + 1];
        prev[head] = head;
        next[head] = head;
        RowCache {
            rows: vec![Vec::new(); l],
            prev,
            next,
            free: entries.max(2 * l),
            spare: Vec::new(),
        }
    }

    fn head(&self) -> usize {
        self.rows.len()
    }

    fn unlink(&mut self, i: usize) {
        let (p, n) = (self.prev[i], self.next[i]);
        self.next[p] = n;
        self.prev[n] = p;
    }

    /// Inserts `i` as the most recently used (just before the head).
    fn link_last(&mut self, i: usize) {
        let head = self.head();
        let last = self.prev[head];
        self.next[last] = i;
        self.prev[i] = last;
        self.next[i] = head;
        self.prev[head] = i;
    }

    fn drop_row(&mut self, i: usize) {
        self.unlink(i);
        self.free += self.rows[i].len();
        let mut old = std::mem::take(&mut self.rows[i]);
        if self.spare.len() < 2 {
            old.clear();
            self.spare.push(old);
        }
    }

    /// Reserves room for row `i` to hold `len` entries, evicting least recently
    /// used rows as needed, marks it most recently used, and returns how many
    /// leading entries are already valid; the caller then appends entries
    /// `filled..len` through [`RowCache::row_vec`] (no zero-filling first).
    pub fn prepare(&mut self, i: usize, len: usize) -> usize {
        let have = self.rows[i].len();
        if have > 0 {
            self.unlink(i);
        }
        if len > have {
            let more = len - have;
            while self.free < more {
                let oldest = self.next[self.head()];
                if oldest == self.head() {
                    break;
                }
                self.drop_row(oldest);
            }
            self.free = self.free.saturating_sub(more);
            if have == 0 {
                if let Some(buf) = self.spare.pop() {
                    self.rows[i] = buf;
                }
            }
            self.rows[i].reserve_exact(more);
        }
        self.link_last(i);
        have.min(len)
    }

    /// Row `i` as far as it is cached.
    #[inline]
    pub fn row(&self, i: usize) -> &[f32] {
        &self.rows[i]
    }

    /// Row `i`'s buffer, to append what [`RowCache::prepare`] reserved.
    #[inline]
    pub fn row_vec(&mut self, i: usize) -> &mut Vec<f32> {
        &mut self.rows[i]
    }

    /// Follows the solver's swap of indices `i` and `j`: swaps the two rows and,
    /// in every other cached row, columns `i` and `j` — or drops a row whose prefix
    /// covers only one of them (libsvm `Cache::swap_index`).
    pub fn swap_index(&mut self, i: usize, j: usize) {
        if i == j {
            return;
        }
        if !self.rows[i].is_empty() {
            self.unlink(i);
        }
        if !self.rows[j].is_empty() {
            self.unlink(j);
        }
        self.rows.swap(i, j);
        if !self.rows[i].is_empty() {
            self.link_last(i);
        }
        if !self.rows[j].is_empty() {
            self.link_last(j);
        }
        let (lo, hi) = if i < j { (i, j) } else { (j, i) };
        let head = self.head();
        let mut h = self.next[head];
        while h != head {
            let after = self.next[h];
            let len = self.rows[h].len();
            if len > lo {
                if len > hi {
                    self.rows[h].swap(lo, hi);
                } else {
                    self.drop_row(h);
                }
            }
            h = after;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_recently_used_row_is_evicted_first() {
        // Budget of 2 full rows of 4 (the minimum).
        let mut c = RowCache::new(4, 0.0);
        assert_eq!(c.prepare(0, 4), 0);
        c.row_vec(0).extend([1.0, 2.0, 3.0, 4.0]);
        assert_eq!(c.prepare(1, 4), 0);
        c.row_vec(1).extend([0.0; 4]);
        assert_eq!(c.prepare(0, 4), 4); // hit; 1 becomes the oldest
        assert_eq!(c.prepare(2, 4), 0); // evicts 1
        c.row_vec(2).extend([0.0; 4]);
        assert_eq!(c.prepare(0, 4), 4);
        assert_eq!(c.prepare(1, 4), 0);
    }

    #[test]
    fn swapping_indices_permutes_cached_columns_and_drops_partial_rows() {
        let mut c = RowCache::new(4, 1.0);
        c.prepare(0, 4);
        c.row_vec(0).extend([1.0, 2.0, 3.0, 4.0]);
        c.prepare(1, 2);
        c.row_vec(1).extend([5.0, 6.0]);
        c.swap_index(1, 3);
        assert_eq!(c.row(0), &[1.0, 4.0, 3.0, 2.0]);
        // Row 1 moved to 3, and its prefix of 2 covers column 1 but not 3: dropped.
        assert!(c.row(3).is_empty());
        assert!(c.row(1).is_empty());
        // A growing row keeps its valid prefix.
        assert_eq!(c.prepare(0, 4), 4);
    }
}
