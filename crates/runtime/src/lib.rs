//! scattertrack-runtime: the real-time stream processor of the TurboTrack
//! pipeline (thesis §6, "Real-time Processing"): a multi-threaded pipeline,
//! so the frame rate is decoupled from the latency.
//!
//! ```text
//!  capture ──► antenna jobs ──► workers ──────────► fusion ──────► tracker ──► outputs
//!  (paced:      one reply window   timing, symbol     joint          engine.step
//!   recorded    per rx antenna     sums, detection    preamble       per tag
//!   speed or                       feature            search, tag
//!   as fast as                     (`AntennaWorker`)  channel,
//!   possible)                                         calibration
//!                                                     (`ReplyFusion`),
//!                                                     in reply order
//! ```
//!
//! [`Workers`] says how jobs meet threads: `Team` (threads = cores,
//! capture among them; the thread completing a reply fuses and tracks it;
//! idle workers pre-woken before a paced reply), or the thesis's pools per
//! antenna / one shared pool with a fusion thread. All give the same output.
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
