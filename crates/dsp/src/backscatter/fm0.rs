//! FM0 (bi-phase space) chip encoder, EPC Gen2 §6.3.1.3.2.

/// The FM0 preamble `1 0 1 0 v 1` in chips (two per bit, starting high).
pub(super) const PREAMBLE: [u8; 12] = [1, 1, 0, 1, 0, 0, 1, 0, 0, 0, 1, 1];

/// Chips of an FM0 reply: optional TRext pilot (12 data-0), the preamble,
/// `bits`, and (with `end`) the dummy data-1.
///
/// FM0 inverts the level at every bit boundary; a data-0 also inverts in
/// the middle of the bit. The pilot is chosen to end low so that the
/// preamble's first chip (high) is the inversion that FM0 requires.
pub(super) fn encode(trext: bool, bits: &[u8], end: bool) -> Vec<u8> {
    let mut chips = Vec::with_capacity(24 + PREAMBLE.len() + 2 * bits.len() + 2);
    if trext {
        for _ in 0..12 {
            chips.extend_from_slice(&[1, 0]);
        }
    }
    chips.extend_from_slice(&PREAMBLE);
    let mut level = 1u8; // the preamble ends high
    let tail = if end { Some(1u8) } else { None };
    for bit in bits.iter().copied().map(|b| u8::from(b != 0)).chain(tail) {
        level ^= 1; // boundary inversion
        if bit == 1 {
            chips.extend_from_slice(&[level, level]);
        } else {
            chips.extend_from_slice(&[level, level ^ 1]);
            level ^= 1; // mid-bit inversion
        }
    }
    chips
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bit_boundary_inverts_and_zeros_invert_mid_bit() {
        let bits = [0, 1, 1, 0, 0, 1];
        let chips = encode(false, &bits, true);
        let data = &chips[12..];
        let mut previous = chips[11];
        for (i, pair) in data.chunks(2).enumerate() {
            assert_ne!(pair[0], previous, "bit {i} must start with an inversion");
            let bit = if i < bits.len() { bits[i] } else { 1 };
            assert_eq!(pair[0] == pair[1], bit == 1, "bit {i}");
            previous = pair[1];
        }
    }

    #[test]
    fn trext_pilot_is_a_square_wave_ending_low() {
        let chips = encode(true, &[], false);
        assert_eq!(&chips[..24], [1, 0].repeat(12).as_slice());
        assert_eq!(&chips[24..], &PREAMBLE);
    }
}
