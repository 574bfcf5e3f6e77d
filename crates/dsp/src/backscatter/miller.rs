//! Miller-modulated subcarrier chip encoder, EPC Gen2 §6.3.1.3.2.

/// Chips of a Miller-M reply: pilot of 4 (16 with TRext) data-0 bits, the
/// preamble bits `010111`, `bits`, and (with `end`) the dummy data-1.
///
/// Baseband Miller: a data-1 inverts the phase in the middle of the bit; a
/// data-0 does not, but two successive data-0s invert at their boundary.
/// The baseband (±1, starting +1) multiplies a square-wave subcarrier of
/// `M` cycles per bit (chips `+ − + − …` from each bit's start); chip level
/// = 1 where the product is +1. A half bit is `M` chips, a whole number of
/// subcarrier half periods, so every transition lands on a chip boundary.
pub(super) fn encode(m: usize, trext: bool, bits: &[u8], end: bool) -> Vec<u8> {
    let pilot = if trext { 16 } else { 4 };
    let preamble = [0u8, 1, 0, 1, 1, 1];
    let tail = if end { Some(1u8) } else { None };
    let all: Vec<u8> = std::iter::repeat_n(0u8, pilot)
        .chain(preamble)
        .chain(bits.iter().map(|&b| u8::from(b != 0)))
        .chain(tail)
        .collect();
    let mut chips = Vec::with_capacity(all.len() * 2 * m);
    let mut phase: i8 = 1;
    let mut previous: Option<u8> = None;
    for bit in all {
        if previous == Some(0) && bit == 0 {
            phase = -phase;
        }
        for half in 0..2 {
            if half == 1 && bit == 1 {
                phase = -phase;
            }
            for c in 0..m {
                let subcarrier: i8 = if (half * m + c).is_multiple_of(2) { 1 } else { -1 };
                chips.push(u8::from(phase * subcarrier > 0));
            }
        }
        previous = Some(bit);
    }
    chips
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes by correlating each half bit with the subcarrier: the
    /// baseband phase of each half.
    fn baseband(chips: &[u8], m: usize) -> Vec<i8> {
        chips
            .chunks(m)
            .enumerate()
            .map(|(h, half)| {
                let s: i32 = half
                    .iter()
                    .enumerate()
                    .map(|(c, &l)| {
                        let sub = if ((h % 2) * m + c).is_multiple_of(2) { 1 } else { -1 };
                        sub * if l == 1 { 1 } else { -1 }
                    })
                    .sum();
                if s > 0 {
                    1
                } else {
                    -1
                }
            })
            .collect()
    }

    #[test]
    fn baseband_follows_the_miller_rules() {
        for m in [2, 4, 8] {
            let bits = [1u8, 0, 0, 1, 1, 0];
            let chips = encode(m, false, &bits, true);
            assert_eq!(chips.len(), (4 + 6 + 6 + 1) * 2 * m);
            let halves = baseband(&chips, m);
            let all: Vec<u8> = [0, 0, 0, 0, 0, 1, 0, 1, 1, 1].iter().chain(&bits).chain(&[1]).copied().collect();
            for (i, &bit) in all.iter().enumerate() {
                let (a, b) = (halves[2 * i], halves[2 * i + 1]);
                assert_eq!(a != b, bit == 1, "M={m} bit {i}: mid-bit inversion iff data-1");
                if i > 0 {
                    let boundary = halves[2 * i - 1] != a;
                    assert_eq!(boundary, all[i - 1] == 0 && bit == 0, "M={m} boundary before bit {i}");
                }
            }
        }
    }
}
