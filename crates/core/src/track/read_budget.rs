//! A per-read work budget (GLAC, issue 21): the expensive stages (the
//! initial search, replays through thousands of hypotheses, re-seeding)
//! spend at most `limit` work units per read and carry the rest to the
//! tag's next reads, so that no single read costs much more than the
//! budget's time.
//!
//! One unit is about one hypothesis taken through one read (predict and
//! update, both IMM models: ~0.2 µs); the other stages charge their
//! items in the same currency (see the `*_UNITS` constants where they are
//! spent). An item is started only if the budget left covers its largest
//! cost, except the first item of a read, which always runs (so that the
//! work advances whatever the budget).
//!
//! Two kinds of item: expansions (a hypothesis stepped, an initial
//! candidate triple trilaterated, a point refined or merged), each at most
//! a few dozen units, so a read never expands more than its budget; and
//! the O(n) passes that close a stage (pruning and the estimate after a
//! step, building hypotheses), which take budget but cannot be split:
//! one that does not fit waits for the next read and runs first there, so
//! a read costs at most the larger of the budget and one such pass.

/// The work one read may still do, and what it did.
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    left: u64,
    spent: u64,
    /// Of `spent`, the O(n) passes.
    overhead: u64,
}

impl Budget {
    pub fn new(limit: u64) -> Self {
        Self { left: limit, spent: 0, overhead: 0 }
    }

    /// Unlimited (the one-shot entry points).
    pub fn unlimited() -> Self {
        Self::new(u64::MAX)
    }

    /// Whether an item costing at most `cost` may start now.
    #[inline]
    pub fn affords(&self, cost: u64) -> bool {
        cost <= self.left || self.spent == 0
    }

    /// Charges `cost` units.
    #[inline]
    pub fn spend(&mut self, cost: u64) {
        self.left = self.left.saturating_sub(cost);
        self.spent += cost;
    }

    /// Charges `cost` if affordable; false (nothing charged) otherwise.
    #[inline]
    pub fn try_spend(&mut self, cost: u64) -> bool {
        let ok = self.affords(cost);
        if ok {
            self.spend(cost);
        }
        ok
    }

    /// Charges an O(n) pass (not an expansion) if affordable.
    #[inline]
    pub fn try_spend_overhead(&mut self, cost: u64) -> bool {
        let ok = self.affords(cost);
        if ok {
            self.spend_overhead(cost);
        }
        ok
    }

    /// Charges an O(n) pass (not an expansion).
    #[inline]
    pub fn spend_overhead(&mut self, cost: u64) {
        self.left = self.left.saturating_sub(cost);
        self.spent += cost;
        self.overhead += cost;
    }

    /// Units spent on expansions so far.
    pub fn expanded(&self) -> u64 {
        self.spent - self.overhead
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_item_always_runs_then_the_limit_holds() {
        let mut b = Budget::new(10);
        assert!(b.try_spend(25), "the first item of a read always runs");
        assert!(!b.try_spend(1));
        let mut b = Budget::new(10);
        assert!(b.try_spend(6) && !b.try_spend_overhead(5) && b.try_spend_overhead(3));
        assert_eq!(b.expanded(), 6);
        assert!(b.try_spend(1) && !b.try_spend(1));
    }
}
