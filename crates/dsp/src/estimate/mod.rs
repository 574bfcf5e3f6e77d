//! From per-symbol channels to the tag channel (thesis ch. 4.3 (b), (c) and
//! the closing bullets).
//!
//! Contract:
//! - [`symbol_states`]: edge-flip elimination. Given the detected chip grid
//!   and the chip levels (known for the preamble, decided for the payload,
//!   unknown elsewhere), every symbol is labelled [`SymbolState::High`]
//!   (reflective), [`SymbolState::Low`] (non-reflective),
//!   [`SymbolState::Edge`] (within a guard of a possible state transition:
//!   discarded), [`SymbolState::Outside`] (not in the reply) or
//!   [`SymbolState::Invalid`] (non-finite samples).
//! - [`tag_channel`]: `mean(H | High) − mean(H | Low)` per subcarrier, with
//!   the variance of that estimate.
//! - [`Ema`]: exponential moving average across replies of one tag.
//! - [`Calibration`]: a per-(rx, subcarrier) complex correction from a tag
//!   at a known position, so that calibrated channels follow docs/formats.md §5:
//!   `h(f) = a exp(−j 2π f d / c)`, `d = |tx − tag| + |tag − rx|`.
//!
//! Which state is "reflective": the Gen2 waveform's level 1 (the FM0
//! preamble starts at it). A tag whose level 1 is physically the *less*
//! reflective impedance gives the negated channel — consistently for every
//! reply, because a tag's modulator maps levels to impedances in a fixed
//! way — and the calibration, a complex factor per (rx, subcarrier),
//! absorbs that −1 with the hardware response. A polarity flip between
//! replies (a tag or decoder that inverts the waveform) is caught by the
//! [`Ema`], which aligns each new estimate with its running state.

mod calibration;
mod edges;
mod ema;
mod sums;
mod tag_channel;

pub use calibration::{path_channel, Calibration};
pub use edges::{symbol_states, ChipGrid, SymbolState};
pub use ema::Ema;
pub use sums::SymbolSums;
pub use tag_channel::{tag_channel, tag_channel_from_sums, TagChannel};
