//! The helper's OFDM link (thesis ch. 4.2 and the bullets closing ch. 4.3).
//!
//! Contract:
//! - [`OfdmConfig`]: bandwidth `B` (= complex sample rate), `N` subcarriers
//!   (= FFT size = samples per symbol), RF centre, BLF; its constructor
//!   enforces the design rule `N < B / (2 BLF)` (ch. 4.2).
//! - [`KnownSymbol`]: the transmitted symbol `X(f)`, unit magnitude, DC
//!   dropped, deterministic from a seed; sent back to back, so every symbol
//!   is the next one's cyclic prefix.
//! - [`symbol_timing`]: the first sample of the first whole received symbol
//!   (time-domain correlation with the known symbol).
//! - [`Demodulator`]: per-symbol FFT ÷ `X(f)` → [`ChannelMatrix`]
//!   `H(f, n)`, FFT planned once, buffers reused.
//! - [`ChannelTransform`]: the same map for one (summed) symbol, and the
//!   time-domain filter of a projection of `H` — what the real-time path
//!   uses instead of demodulating every symbol.
//!
//! Subcarrier order everywhere outside the FFT is ascending frequency over
//! the `N − 1` active (non-DC) bins; [`OfdmConfig::subcarrier_frequencies`]
//! gives their RF frequencies. FFTs are unitary (`1/√N`), so with `|X| = 1`
//! the per-sample SNR equals the per-symbol, per-subcarrier SNR of `H`.

mod channel;
mod config;
mod demodulate;
mod symbol;
mod timing;
mod transform;

pub use channel::{as_doubles, as_doubles_mut, as_floats, widen, ChannelMatrix};
pub use config::OfdmConfig;
pub use demodulate::Demodulator;
pub use symbol::KnownSymbol;
pub use timing::{symbol_timing, SymbolTiming};
pub use transform::ChannelTransform;
