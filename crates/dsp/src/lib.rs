//! scattertrack-dsp: one-shot wideband channel estimation for the TurboTrack
//! SDR localization helper (thesis ch. 4). No estimator code, no I/O, no
//! Python; the bindings in `python/src/dsp.rs` are thin wrappers.
//!
//! The helper (1 tx, several rx antennas, one clock) transmits the same OFDM
//! symbol back to back while a UHF RFID tag backscatters its reply. Per rx
//! antenna and per reply window the chain is (ch. 4, Fig. 4-1):
//!
//! 1. [`ofdm::symbol_timing`]: time-domain correlation with the known symbol
//!    finds the first sample of the first whole symbol (ch. 4.3, bullet 3).
//! 2. Demodulation, `H(f, n) = FFT(y_n)/(√N X(f))` on the `N − 1` non-DC
//!    subcarriers (ch. 4.2): [`ofdm::Demodulator`] for every symbol, or —
//!    since it is linear — [`ofdm::ChannelTransform`] on sums of runs of
//!    symbols kept in the time domain ([`estimate::SymbolSums`]), which is
//!    what the reply pipeline does.
//! 3. [`detect`]: a per-symbol detection feature (the paper's
//!    `H_combined(n) = Σ_f |H(f, n)|`, or a coherent projection) correlated
//!    with the Gen2 preamble → reply start and tag BLF (ch. 4.3 (a)).
//! 4. [`estimate::symbol_states`]: edge-flip elimination — symbols within a
//!    guard of a tag state transition are discarded (ch. 4.3 (b)).
//! 5. [`estimate::tag_channel_from_sums`] (or [`estimate::tag_channel`] on
//!    a demodulated matrix): mean(reflective) − mean(non-reflective) per
//!    subcarrier (ch. 4.3 (c)).
//! 6. [`estimate::Ema`] across replies and [`estimate::Calibration`] from a
//!    tag at a known position (ch. 4.3, last bullets).
//!
//! [`reply::ReplyProcessor`] runs 1–5 for all rx antennas of one reply with
//! buffers and FFT plans allocated once; [`reply::AntennaFront`] is its
//! per-antenna half, for a worker thread per antenna.
//!
//! Map of the crate:
//! - [`ofdm`]: configuration and design rule, known symbol, timing, FFT.
//! - [`backscatter`]: Gen2 FM0 / Miller chip waveforms and preambles.
//! - [`detect`]: detection features and the normalised preamble correlation.
//! - [`estimate`]: edge elimination, tag channel, EMA, calibration.
//! - [`reply`]: the per-reply pipeline.
//! - [`lora`]: Marvel's LoRa-backscatter pose sensing (docs/marvel.md
//!   section 7): chirp, dechirp peak, Doppler/CFO, channel phase, range,
//!   MUSIC angle, heading, and the per-epoch chain. Samples there are
//!   `Complex32` or `Complex64` (`lora::Sample`).
//!
//! Units are SI (Hz, s, m); time inside a window is counted in samples
//! (`1 / B` s) or OFDM symbols (`N / B` s), as each doc comment says.
//! Numbers are `f64`; raw samples are `Complex<f32>` (SigMF `cf32`).

pub mod backscatter;
pub mod detect;
pub mod error;
pub mod estimate;
pub mod lora;
pub mod ofdm;
pub mod reply;

pub use error::{Error, Result};
pub use num_complex::{Complex32, Complex64};

/// Speed of light in vacuum, m/s: the workspace's one definition, in the core
/// (re-exported so the DSP's formulas read `crate::SPEED_OF_LIGHT`).
pub use scattertrack_core::scene::SPEED_OF_LIGHT;
