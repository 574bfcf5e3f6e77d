//! A state covariance stored as its upper triangle: 21 numbers instead of
//! 36 for the 6×6 `P`.
//!
//! Why: a tracker that carries hundreds of hypotheses per tag for
//! thousands of tags holds mostly covariances (GLAC: two per hypothesis,
//! one per IMM model). Packing them cuts a hypothesis from about 0.8 kB to
//! 0.5 kB, which bounds the memory of many initialising tags and lets more
//! converged tags' states share the cache. The filter maths still runs on
//! full [`StateMatrix`] values: [`PackedCovariance::unpack`] before a step,
//! [`PackedCovariance::pack`] after it.
//!
//! Packing symmetrises: element (i, j) is stored as (P_ij + P_ji) / 2, the
//! nearest symmetric matrix in the Frobenius norm. Products such as F P Fᵀ
//! are symmetric only up to rounding (their two triangles are summed in
//! different orders); keeping one value per pair stops that asymmetry from
//! accumulating over thousands of steps.

use crate::model::{StateMatrix, STATE};

/// Stored values: the upper triangle, row by row.
pub const PACKED: usize = STATE * (STATE + 1) / 2;

/// A symmetric `STATE`×`STATE` matrix as its upper triangle (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PackedCovariance {
    upper: [f64; PACKED],
}

/// For each element of a full matrix (nalgebra's column-major order), its
/// index in the packed upper triangle: a constant table, so that packing
/// and unpacking unroll into straight loads and stores (they run several
/// times per hypothesis and read).
const PACKED_INDEX: [usize; STATE * STATE] = {
    let mut table = [0; STATE * STATE];
    let mut column = 0;
    while column < STATE {
        let mut row = 0;
        while row < STATE {
            let (i, j) = if row <= column { (row, column) } else { (column, row) };
            // Row i of the upper triangle starts after i rows of STATE, STATE − 1, … values.
            table[column * STATE + row] = i * STATE - i * (i.saturating_sub(1)) / 2 - i + j;
            row += 1;
        }
        column += 1;
    }
    table
};

/// For each packed value, its (row, column) in the upper triangle, as
/// column-major indices of the element and of its mirror.
const FULL_INDEX: [(usize, usize); PACKED] = {
    let mut table = [(0, 0); PACKED];
    let mut k = 0;
    let mut i = 0;
    while i < STATE {
        let mut j = i;
        while j < STATE {
            table[k] = (j * STATE + i, i * STATE + j);
            k += 1;
            j += 1;
        }
        i += 1;
    }
    table
};

impl PackedCovariance {
    /// The symmetric part of `p`, packed.
    #[inline]
    pub fn pack(p: &StateMatrix) -> Self {
        let full = p.as_slice();
        let mut upper = [0.0; PACKED];
        for (value, &(upper_index, mirror)) in upper.iter_mut().zip(FULL_INDEX.iter()) {
            *value = 0.5 * (full[upper_index] + full[mirror]);
        }
        Self { upper }
    }

    /// The full matrix.
    #[inline]
    pub fn unpack(&self) -> StateMatrix {
        let mut full = [0.0; STATE * STATE];
        for (value, &k) in full.iter_mut().zip(PACKED_INDEX.iter()) {
            *value = self.upper[k];
        }
        StateMatrix::from_column_slice(&full)
    }
}

/// Both IMM models' covariances, unpacked.
#[inline]
pub fn unpack_pair(p: &[PackedCovariance; 2]) -> [StateMatrix; 2] {
    [p[0].unpack(), p[1].unpack()]
}

/// Both IMM models' covariances, packed.
#[inline]
pub fn pack_pair(p: &[StateMatrix; 2]) -> [PackedCovariance; 2] {
    [PackedCovariance::pack(&p[0]), PackedCovariance::pack(&p[1])]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn symmetric(seed: u64) -> StateMatrix {
        // A deterministic SPD matrix: A Aᵀ + I.
        let a = StateMatrix::from_fn(|i, j| (((i * 7 + j * 3) as u64 + seed) % 11) as f64 * 0.1 - 0.5);
        a * a.transpose() + StateMatrix::identity()
    }

    #[test]
    fn a_symmetric_matrix_round_trips_exactly() {
        for seed in 0..5 {
            let p = symmetric(seed);
            assert_eq!(PackedCovariance::pack(&p).unpack(), p);
        }
    }

    #[test]
    fn packing_keeps_the_symmetric_part() {
        let p = symmetric(1);
        let mut skewed = p;
        skewed[(0, 4)] += 1e-3;
        skewed[(4, 0)] -= 1e-3;
        let back = PackedCovariance::pack(&skewed).unpack();
        assert!((back - p).abs().max() < 1e-15);
        assert_eq!(back, back.transpose());
    }

    #[test]
    fn the_index_tables_agree() {
        // Row-major upper triangle: (0,0) (0,1) … (0,5) (1,1) … (5,5).
        let mut k = 0;
        for i in 0..STATE {
            for j in i..STATE {
                assert_eq!(PACKED_INDEX[j * STATE + i], k);
                assert_eq!(PACKED_INDEX[i * STATE + j], k);
                assert_eq!(FULL_INDEX[k], (j * STATE + i, i * STATE + j));
                k += 1;
            }
        }
    }

    #[test]
    fn a_pair_round_trips() {
        let pair = [symmetric(2), symmetric(3)];
        assert_eq!(unpack_pair(&pack_pair(&pair)), pair);
        assert_eq!(std::mem::size_of::<PackedCovariance>(), PACKED * 8);
    }
}
