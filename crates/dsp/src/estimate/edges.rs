/// What a symbol is used for after edge-flip elimination.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum SymbolState {
    /// Before the reply or after the last chip whose level is known.
    Outside = 0,
    /// Within the guard of a (possible) state transition, or inside a chip
    /// whose level is unknown: corrupted, discarded (ch. 4.3 (b)).
    Edge = 1,
    /// Demodulated from non-finite samples.
    Invalid = 2,
    /// Wholly inside a level-0 (non-reflective) run.
    Low = 3,
    /// Wholly inside a level-1 (reflective) run.
    High = 4,
}

/// The tag's chip grid in symbol units, from the detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChipGrid {
    /// Start of chip 0, symbols from the first whole symbol (fractional).
    pub start_symbol: f64,
    /// Chip length (half a BLF period), symbols.
    pub chip_symbols: f64,
    /// Guard on each side of a transition, symbols: covers the timing error
    /// of the detection, the tag's switching time and the channel's delay
    /// spread.
    pub guard_symbols: f64,
    /// Extra guard per chip of distance from `reference_chip`, symbols: the
    /// residual BLF uncertainty (`chip_symbols × scale_uncertainty`) makes
    /// boundaries far from the preamble less certain.
    pub drift_per_chip: f64,
    /// The chip where the grid is best known (the preamble's centre).
    pub reference_chip: f64,
}

impl ChipGrid {
    /// Time of boundary `i` (start of chip `i`), symbols.
    #[inline]
    pub fn boundary(&self, i: usize) -> f64 {
        self.start_symbol + i as f64 * self.chip_symbols
    }

    /// Guard around boundary `i`, symbols.
    #[inline]
    pub fn guard(&self, i: usize) -> f64 {
        self.guard_symbols + self.drift_per_chip * (i as f64 - self.reference_chip).abs()
    }
}

/// Edge-flip elimination (thesis ch. 4.3 (b)): labels each of `valid.len()`
/// symbols from the chip grid and the chip levels into `out`.
///
/// `levels[i]` is chip `i`'s level (`Some(0 | 1)`) or `None` when unknown
/// (an undecodable payload chip). Consecutive chips of the same known level
/// form a run: only run boundaries are transitions (e.g. the FM0 preamble's
/// `11` and `000` have none inside). Symbol `n` covers `[n, n + 1)`; it gets
/// the run's level when `[n, n+1)` lies within
/// `[boundary + guard, next boundary − guard]`; a symbol overlapping the
/// reply (from chip 0's boundary minus its guard to the last known chip's
/// end plus its guard) that is not inside a run is [`SymbolState::Edge`];
/// the rest is [`SymbolState::Outside`]. Chips after the first unknown one
/// still count if known. Invalid symbols are [`SymbolState::Invalid`]
/// whatever else holds. Cost `O(symbols + chips)`.
pub fn symbol_states(grid: &ChipGrid, levels: &[Option<u8>], valid: &[bool], out: &mut Vec<SymbolState>) {
    let symbols = valid.len();
    out.clear();
    out.resize(symbols, SymbolState::Outside);
    let last_known = levels.iter().rposition(|l| l.is_some());
    if let Some(last) = last_known {
        if grid.chip_symbols > 0.0 && grid.chip_symbols.is_finite() {
            // Everything overlapping the reply starts as Edge ...
            let span_start = grid.boundary(0) - grid.guard(0);
            let span_end = grid.boundary(last + 1) + grid.guard(last + 1);
            let first = span_start.floor().max(0.0) as usize;
            let end = (span_end.ceil().max(0.0) as usize).min(symbols);
            for state in out.iter_mut().take(end).skip(first) {
                *state = SymbolState::Edge;
            }
            // ... and runs of one known level claim their inner symbols.
            let mut i = 0;
            while i <= last {
                let Some(level) = levels[i] else {
                    i += 1;
                    continue;
                };
                let mut j = i + 1;
                while j <= last && levels[j] == Some(level) {
                    j += 1;
                }
                let from = grid.boundary(i) + grid.guard(i);
                let to = grid.boundary(j) - grid.guard(j);
                let state = if level == 0 { SymbolState::Low } else { SymbolState::High };
                let first = from.ceil().max(0.0) as usize;
                let stop = ((to - 1.0).floor() + 1.0).max(0.0) as usize; // n + 1 ≤ to
                for s in out.iter_mut().take(stop.min(symbols)).skip(first) {
                    *s = state;
                }
                i = j;
            }
        }
    }
    for (s, &ok) in out.iter_mut().zip(valid) {
        if !ok {
            *s = SymbolState::Invalid;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(start: f64, chip: f64, guard: f64) -> ChipGrid {
        ChipGrid {
            start_symbol: start,
            chip_symbols: chip,
            guard_symbols: guard,
            drift_per_chip: 0.0,
            reference_chip: 0.0,
        }
    }

    fn count(states: &[SymbolState], which: SymbolState) -> usize {
        states.iter().filter(|&&s| s == which).count()
    }

    #[test]
    fn counts_follow_the_guard_and_merge_equal_chips() {
        // Chips of 10 symbols from symbol 5: levels 1 1 0 1, guard 1.
        let levels = [Some(1), Some(1), Some(0), Some(1)];
        let mut out = Vec::new();
        symbol_states(&grid(5.0, 10.0, 1.0), &levels, &[true; 60], &mut out);
        // Run 1: [5, 25) → symbols 6..=23 (18); run 0: [25, 35) → 26..=33 (8);
        // run 1: [35, 45) → 36..=43 (8).
        assert_eq!(count(&out, SymbolState::High), 26);
        assert_eq!(count(&out, SymbolState::Low), 8);
        // Reply span [4, 46): 42 symbols, 34 in runs → 8 edges.
        assert_eq!(count(&out, SymbolState::Edge), 8);
        assert_eq!(count(&out, SymbolState::Outside), 60 - 42);
        assert_eq!(out[15], SymbolState::High); // inside the merged 11: no edge
        assert_eq!(out[24], SymbolState::Edge);
        assert_eq!(out[25], SymbolState::Edge);
        assert_eq!(out[3], SymbolState::Outside);
    }

    #[test]
    fn fractional_boundaries_discard_straddling_symbols() {
        let levels = [Some(1), Some(0)];
        let mut out = Vec::new();
        symbol_states(&grid(2.5, 4.0, 0.0), &levels, &[true; 12], &mut out);
        // Run 1: [2.5, 6.5) → symbols 3, 4, 5; run 0: [6.5, 10.5) → 7, 8, 9.
        assert_eq!(
            &out[2..11],
            &[
                SymbolState::Edge,
                SymbolState::High,
                SymbolState::High,
                SymbolState::High,
                SymbolState::Edge,
                SymbolState::Low,
                SymbolState::Low,
                SymbolState::Low,
                SymbolState::Edge
            ]
        );
    }

    #[test]
    fn unknown_chips_and_invalid_symbols_are_not_used() {
        let levels = [Some(1), None, Some(0)];
        let mut valid = vec![true; 40];
        valid[3] = false;
        let mut out = Vec::new();
        symbol_states(&grid(0.0, 10.0, 0.5), &levels, &valid, &mut out);
        assert_eq!(out[3], SymbolState::Invalid);
        assert!(out[10..20].iter().all(|&s| s == SymbolState::Edge));
        assert_eq!(count(&out, SymbolState::Low), 8);
        // No known level: nothing is in the reply.
        symbol_states(&grid(0.0, 10.0, 0.5), &[None, None], &[true; 40], &mut out);
        assert_eq!(count(&out, SymbolState::Outside), 40);
    }

    #[test]
    fn drift_widens_guards_away_from_the_reference() {
        let levels = [Some(1), Some(0), Some(1), Some(0), Some(1), Some(0)];
        let g = ChipGrid {
            start_symbol: 0.0,
            chip_symbols: 10.0,
            guard_symbols: 1.0,
            drift_per_chip: 0.5,
            reference_chip: 0.0,
        };
        let mut out = Vec::new();
        symbol_states(&g, &levels, &[true; 60], &mut out);
        // Chip 0: [0+1, 10−1.5] → symbols 1..=7 (7); chip 5: [50+3.5, 60−4] → 54, 55 (2).
        let first = out[..10].iter().filter(|&&s| s == SymbolState::High).count();
        let last = out[50..].iter().filter(|&&s| s == SymbolState::Low).count();
        assert_eq!((first, last), (7, 2));
    }
}
