//! The tag side: EPC Gen2 (UHF RFID) backscatter waveforms as chip levels.
//!
//! Contract: a tag reply is a sequence of *chips*, each half a BLF period
//! (`1 / (2 BLF)` s) long, at level 1 or 0. Every FM0 and Miller state
//! transition falls on a chip boundary, and a chip is the shortest constant
//! state, which is why the design rule of ch. 4.2 compares the OFDM symbol
//! with `1 / (2 BLF)`. Level 1 is the waveform's high level as the Gen2
//! figures draw it (the FM0 preamble starts high); this crate calls it the
//! *reflective* state (see `estimate::tag_channel` for why the physical sign
//! does not matter after calibration).
//!
//! - [`Encoding`]: FM0 (2 chips per bit) or Miller M = 2, 4, 8 (2M chips per
//!   bit: M subcarrier cycles).
//! - [`preamble_chips`]: the Gen2 preamble, with the TRext pilot when asked.
//! - [`reply_chips`]: preamble + data bits + the dummy 1 that ends the reply.

mod fm0;
mod miller;

use crate::error::{Error, Result};

/// Tag-to-reader data encoding (Gen2 `M` field of Query).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// FM0 (bi-phase space): data rate = BLF.
    Fm0,
    /// Miller-modulated subcarrier with `M ∈ {2, 4, 8}` subcarrier cycles
    /// per bit: data rate = BLF / M.
    Miller(u8),
}

impl Encoding {
    /// Parses `"fm0"`, `"miller2"`, `"miller4"` or `"miller8"` (also `"m2"`…).
    pub fn parse(name: &str) -> Result<Self> {
        match name.trim().to_ascii_lowercase().as_str() {
            "fm0" => Ok(Encoding::Fm0),
            "miller2" | "m2" => Ok(Encoding::Miller(2)),
            "miller4" | "m4" => Ok(Encoding::Miller(4)),
            "miller8" | "m8" => Ok(Encoding::Miller(8)),
            other => Err(Error::BadConfig(format!("unknown encoding '{other}' (fm0, miller2, miller4, miller8)"))),
        }
    }

    /// The canonical name, as [`Encoding::parse`] reads it.
    pub fn name(&self) -> &'static str {
        match self {
            Encoding::Fm0 => "fm0",
            Encoding::Miller(2) => "miller2",
            Encoding::Miller(4) => "miller4",
            Encoding::Miller(8) => "miller8",
            Encoding::Miller(_) => "miller?",
        }
    }

    /// Checks `M ∈ {2, 4, 8}`.
    pub fn validate(&self) -> Result<()> {
        match self {
            Encoding::Fm0 | Encoding::Miller(2 | 4 | 8) => Ok(()),
            Encoding::Miller(m) => Err(Error::BadConfig(format!("Miller M must be 2, 4 or 8, got {m}"))),
        }
    }

    /// Chips (half BLF periods) per data bit: 2 for FM0, `2M` for Miller.
    pub fn chips_per_bit(&self) -> usize {
        match self {
            Encoding::Fm0 => 2,
            Encoding::Miller(m) => 2 * *m as usize,
        }
    }
}

/// The Gen2 preamble as chip levels (0/1), pilot first when `trext`.
///
/// FM0: `1 0 1 0 v 1` (v: the FM0 violation) = chips `110100100011`; with
/// TRext a pilot of 12 data-0 bits precedes it. Miller: a pilot of 4
/// (TRext = 0) or 16 (TRext = 1) data-0 bits, then `010111`, on the
/// subcarrier.
pub fn preamble_chips(encoding: Encoding, trext: bool) -> Result<Vec<u8>> {
    encoding.validate()?;
    Ok(match encoding {
        Encoding::Fm0 => fm0::encode(trext, &[], false),
        Encoding::Miller(m) => miller::encode(m as usize, trext, &[], false),
    })
}

/// A whole reply as chip levels: preamble, `bits` (each 0 or 1; any
/// non-zero value counts as 1), then the dummy data-1 that ends every Gen2
/// reply.
pub fn reply_chips(encoding: Encoding, trext: bool, bits: &[u8]) -> Result<Vec<u8>> {
    encoding.validate()?;
    Ok(match encoding {
        Encoding::Fm0 => fm0::encode(trext, bits, true),
        Encoding::Miller(m) => miller::encode(m as usize, trext, bits, true),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_m_is_rejected() {
        for e in [Encoding::Fm0, Encoding::Miller(2), Encoding::Miller(4), Encoding::Miller(8)] {
            assert_eq!(Encoding::parse(e.name()).unwrap(), e);
        }
        assert!(Encoding::parse("miller3").is_err());
        assert!(preamble_chips(Encoding::Miller(3), false).is_err());
    }

    #[test]
    fn preamble_lengths() {
        assert_eq!(preamble_chips(Encoding::Fm0, false).unwrap().len(), 12);
        assert_eq!(preamble_chips(Encoding::Fm0, true).unwrap().len(), 36);
        assert_eq!(preamble_chips(Encoding::Miller(4), false).unwrap().len(), 10 * 8);
        assert_eq!(preamble_chips(Encoding::Miller(2), true).unwrap().len(), 22 * 4);
        assert_eq!(reply_chips(Encoding::Fm0, false, &[1, 0, 1]).unwrap().len(), 12 + 6 + 2);
    }

    #[test]
    fn no_state_is_shorter_than_one_chip_and_none_longer_than_two() {
        // The design rule relies on the shortest constant state being one chip.
        for e in [Encoding::Fm0, Encoding::Miller(2), Encoding::Miller(4), Encoding::Miller(8)] {
            let chips = reply_chips(e, true, &[1, 1, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1]).unwrap();
            let mut run = 1;
            for w in chips.windows(2) {
                if w[0] == w[1] {
                    run += 1;
                } else {
                    run = 1;
                }
                assert!(run <= 3, "{e:?}: a state of {run} chips");
            }
        }
    }
}
