//! A hasher for the particle filter's packed candidate-index keys (u64,
//! `turbotrack::pack`). The keys come from our own packing, not from
//! outside input, so the standard library's DoS-resistant SipHash buys
//! nothing here; at two look-ups per particle per frame it cost several
//! microseconds a frame. One multiply by an odd 64-bit constant (Fibonacci
//! hashing, Knuth vol. 3 §6.4) spreads the packed bytes over the high bits
//! that the table uses.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Fibonacci hashing of one `u64`; other writes fold their bytes in.
#[derive(Debug, Default, Clone, Copy)]
pub struct KeyHasher(u64);

/// 2⁶⁴ / φ, odd.
const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

impl Hasher for KeyHasher {
    #[inline]
    fn write_u64(&mut self, key: u64) {
        self.0 = (self.0 ^ key).wrapping_mul(GOLDEN);
    }

    fn write(&mut self, bytes: &[u8]) {
        // Eight bytes at a time: an `[i64; 3]` grid cell arrives as one
        // 24-byte write (after its 8-byte length prefix).
        let mut words = bytes.chunks_exact(8);
        for word in &mut words {
            self.write_u64(u64::from_le_bytes(word.try_into().expect("eight bytes")));
        }
        for &b in words.remainder() {
            self.write_u64(b as u64);
        }
    }

    #[inline]
    fn finish(&self) -> u64 {
        // The table indexes by the low bits: fold the well-mixed high half in.
        self.0 ^ (self.0 >> 32)
    }
}

/// A `HashMap` keyed by packed candidate indices.
pub type KeyMap<V> = HashMap<u64, V, BuildHasherDefault<KeyHasher>>;

/// A `HashMap` keyed by integer grid cells (the initial search's and
/// re-seeding's merge grids): our own keys again, looked up 27 times per
/// candidate, where SipHash cost about a tenth of a busy engine's time.
pub type CellMap<V> = HashMap<[i64; 3], V, BuildHasherDefault<KeyHasher>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_that_differ_in_one_byte_land_apart() {
        let hash = |k: u64| {
            let mut h = KeyHasher::default();
            h.write_u64(k);
            h.finish()
        };
        let base = 0x8080_8080u64;
        // Four receivers: the low four bytes, each one tooth up or down.
        let mut seen: Vec<u64> = (0..4).flat_map(|byte| [base + (1 << (8 * byte)), base - (1 << (8 * byte))]).map(|k| hash(k) & 0xff).collect();
        seen.sort();
        seen.dedup();
        // 8 neighbouring keys in 8 of 256 buckets.
        assert_eq!(seen.len(), 8, "{seen:?}");
        let mut map: KeyMap<u32> = KeyMap::default();
        map.insert(base, 1);
        assert_eq!(map.get(&base), Some(&1));
    }

    /// Neighbouring grid cells spread over the table's low bits.
    #[test]
    fn neighbouring_cells_land_apart() {
        let hash = |c: [i64; 3]| {
            use std::hash::{BuildHasher, BuildHasherDefault};
            BuildHasherDefault::<KeyHasher>::default().hash_one(c)
        };
        let mut seen: Vec<u64> = (-1..=1)
            .flat_map(|x| (-1..=1).flat_map(move |y| (-1..=1).map(move |z| [x + 40, y - 7, z + 1000])))
            .map(|c| hash(c) & 0x3ff)
            .collect();
        seen.sort();
        seen.dedup();
        assert!(seen.len() >= 25, "27 neighbours in {} of 1024 buckets", seen.len());
        let mut map: CellMap<u32> = CellMap::default();
        map.insert([1, -2, 3], 7);
        assert_eq!(map.get(&[1, -2, 3]), Some(&7));
        assert_eq!(map.get(&[1, -2, 4]), None);
    }
}
