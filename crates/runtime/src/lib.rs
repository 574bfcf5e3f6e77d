//! scattertrack-runtime: the real-time stream processor of the TurboTrack
//! pipeline (thesis §6, "Real-time Processing"): a multi-threaded pipeline
//! with worker pools, so the frame rate is decoupled from the latency.
//!
//! ```text
//!  capture ──► per-antenna queues ──► workers (k per antenna) ──► fusion ──► tracker ──► outputs
//!  (paced:      one reply window        timing, FFT per symbol,    joint       engine.step
//!   recorded    per rx antenna          detection feature          preamble    per tag
//!   speed or                            (`AntennaWorker`)          search, tag
//!   as fast as                                                    channel,
//!   possible)                                                     calibration
//!                                                                 (`ReplyFusion`),
//!                                                                 in reply order
//! ```
//!
//! Contract: [`run`] consumes [`Reply`]s (one tag reply: the IQ window of
//! every receive antenna) in capture order and returns one [`Output`] per
//! reply, in the same order, with the latency from the reply's *arrival*
//! (the moment capture hands it to the pipeline) to the tracker's output.
//! Replies whose channel no antenna could estimate are counted, never
//! dropped silently; replies the fusion declines are counted by reason.
//! The crate knows nothing of Python or file formats. The stages are
//! traits ([`AntennaWorker`], [`ReplyFusion`]) so the pipeline is tested
//! alone with stand-ins; [`dsp`] implements them over `scattertrack-dsp`
//! (the per-antenna half of the DSP on the workers, the joint half on the
//! fusion thread).

pub mod dsp;
mod pipeline;
pub mod source;

pub use pipeline::{
    run, run_source, AntennaWorker, InMemory, ReplySource, ChannelEstimator, Output, Pacing, PassThroughFusion, PerAntenna, Reply, ReplyFusion, ReplyHeader,
    RunReport, RuntimeConfig, Workers, STAGES,
};
