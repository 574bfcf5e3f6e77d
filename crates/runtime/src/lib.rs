//! scattertrack-runtime: the real-time stream processor of the TurboTrack
//! pipeline (thesis §6, "Real-time Processing"): a multi-threaded pipeline
//! with worker pools, so the frame rate is decoupled from the latency.
//!
//! ```text
//!  capture ──► per-antenna queues ──► workers (k per antenna) ──► fusion ──► tracker ──► outputs
//!  (paced:      one reply window        channel estimation:        all rx of   engine.step
//!   recorded    per rx antenna          IQ → tag channel h(f)      one reply   per tag
//!   speed or                            (any `ChannelEstimator`)   → frame,
//!   as fast as                                                    in reply
//!   possible)                                                     order
//! ```
//!
//! Contract: [`run`] consumes [`Reply`]s (one tag reply: the IQ window of
//! every receive antenna) in capture order and returns one [`Output`] per
//! reply, in the same order, with the latency from the reply's *arrival*
//! (the moment capture hands it to the pipeline) to the tracker's output.
//! Replies whose channel no antenna could estimate are counted, never
//! dropped silently. The crate knows nothing of Python or file formats;
//! the DSP sits behind [`ChannelEstimator`] (implemented over
//! `scattertrack-dsp` by the caller), so the pipeline is tested alone.

mod pipeline;

pub use pipeline::{run, ChannelEstimator, Output, Pacing, Reply, RunReport, RuntimeConfig};
