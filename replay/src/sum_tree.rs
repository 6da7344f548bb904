//! A sum-tree over a fixed number of slots: prefix-sum search for
//! proportional sampling, with the total and the minimum positive value
//! kept at the root.

/// Non-negative weights in `capacity` slots, in a complete binary tree
/// whose inner nodes hold their children's sums and minimums.
///
/// Cost: [`set`](Self::set) and [`find`](Self::find) are O(log n);
/// [`total`](Self::total) and [`min`](Self::min) are O(1). Memory: 24 bytes
/// per slot, slots rounded up to a power of two (f64 sums and f32 minimums
/// for leaves and inner nodes). Inner
/// sums are recomputed from the children on every update, never adjusted
/// by differences, so rounding errors do not accumulate. Not thread-safe;
/// the table holds it behind its lock.
#[derive(Debug, Clone)]
pub struct SumTree {
    /// Leaves in `leaves..2 * leaves`, root at 1, index 0 unused.
    sums: Vec<f64>,
    /// Minimum positive leaf below each node; infinity when none.
    mins: Vec<f32>,
    leaves: usize,
    capacity: usize,
}

impl SumTree {
    /// A tree of `capacity` slots, all zero.
    pub fn new(capacity: usize) -> Self {
        let leaves = capacity.max(1).next_power_of_two();
        Self {
            sums: vec![0.0; 2 * leaves],
            mins: vec![f32::INFINITY; 2 * leaves],
            leaves,
            capacity,
        }
    }

    /// Number of slots.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes held by the tree.
    pub fn bytes(&self) -> usize {
        self.sums.len() * 8 + self.mins.len() * 4
    }

    /// Sets slot `i` to `value` (finite, >= 0; 0 makes it unsampleable).
    pub fn set(&mut self, i: usize, value: f64) {
        debug_assert!(i < self.capacity && value >= 0.0 && value.is_finite());
        let mut node = self.leaves + i;
        self.sums[node] = value;
        self.mins[node] = if value > 0.0 {
            value as f32
        } else {
            f32::INFINITY
        };
        while node > 1 {
            node /= 2;
            let (l, r) = (2 * node, 2 * node + 1);
            self.sums[node] = self.sums[l] + self.sums[r];
            self.mins[node] = self.mins[l].min(self.mins[r]);
        }
    }

    /// The value of slot `i`.
    pub fn get(&self, i: usize) -> f64 {
        self.sums[self.leaves + i]
    }

    /// Sum of every slot.
    pub fn total(&self) -> f64 {
        self.sums[1]
    }

    /// Smallest positive slot value, if any.
    pub fn min(&self) -> Option<f64> {
        let m = self.mins[1];
        m.is_finite().then_some(f64::from(m))
    }

    /// The slot whose cumulative range contains `mass` in `[0, total)`:
    /// slot `i` is found with probability `value_i / total` when `mass` is
    /// uniform. Never returns a zero slot while the total is positive;
    /// `None` when the total is zero.
    pub fn find(&self, mass: f64) -> Option<usize> {
        if self.total() <= 0.0 {
            return None;
        }
        let mut mass = mass.clamp(0.0, self.total());
        let mut node = 1;
        while node < self.leaves {
            let (l, r) = (2 * node, 2 * node + 1);
            // Go right only where there is weight; rounding can leave
            // `mass` a hair above a left sum whose right sibling is empty.
            if mass < self.sums[l] || self.sums[r] <= 0.0 {
                node = l;
            } else {
                mass -= self.sums[l];
                node = r;
            }
        }
        Some(node - self.leaves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_minimums_and_search() {
        let mut t = SumTree::new(5);
        for (i, v) in [1.0, 0.0, 3.0, 2.0, 4.0].into_iter().enumerate() {
            t.set(i, v);
        }
        assert_eq!(t.total(), 10.0);
        assert_eq!(t.min(), Some(1.0), "zero slots are not the minimum");
        assert_eq!(t.find(0.0), Some(0));
        assert_eq!(t.find(0.999), Some(0));
        assert_eq!(t.find(1.0), Some(2), "slot 1 is empty, skipped");
        assert_eq!(t.find(3.999), Some(2));
        assert_eq!(t.find(4.0), Some(3));
        assert_eq!(t.find(6.0), Some(4));
        assert_eq!(
            t.find(10.0),
            Some(4),
            "the end maps to the last non-empty slot"
        );
        t.set(4, 0.0);
        assert_eq!(t.find(9.0), Some(3));
        assert_eq!(t.total(), 6.0);
        t.set(0, 0.0);
        assert_eq!(t.min(), Some(2.0));
    }

    #[test]
    fn empty_tree_finds_nothing() {
        let t = SumTree::new(3);
        assert_eq!(t.find(0.0), None);
        assert_eq!(t.min(), None);
    }

    #[test]
    fn repeated_updates_do_not_drift() {
        let mut t = SumTree::new(1000);
        for round in 0..50 {
            for i in 0..1000 {
                t.set(i, ((i * 7 + round) % 13) as f64 * 0.1);
            }
        }
        let exact: f64 = (0..1000).map(|i| ((i * 7 + 49) % 13) as f64 * 0.1).sum();
        assert!((t.total() - exact).abs() < 1e-9, "{} vs {exact}", t.total());
    }
}
