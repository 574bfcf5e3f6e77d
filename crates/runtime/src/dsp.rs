//! The helper's DSP (`scattertrack-dsp`, thesis ch. 4) as the pipeline's two
//! stages: [`DspWorker`] runs one antenna's symbol timing, symbol prefix
//! sums and detection feature ([`AntennaFront`]) on a worker thread;
//! [`DspFusion`] runs the joint preamble search, edge-flip elimination and
//! tag channel ([`ReplyProcessor::finish`]), then the calibration and the
//! optional per-tag EMA, on the fusion thread.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use num_complex::Complex64;
use scattertrack_dsp::estimate::Ema;
use scattertrack_dsp::ofdm::{KnownSymbol, OfdmConfig};
use scattertrack_dsp::reply::{AntennaFront, AntennaSymbols, ReplyOptions, ReplyProcessor};
use scattertrack_dsp::{Error, Result};

use crate::pipeline::{AntennaWorker, Reply, ReplyFusion, ReplyHeader};

/// Everything the DSP stages share: the helper's design, the reply options,
/// the per-rx timing reference (learnt on the calibration recording) and
/// the calibration.
#[derive(Debug, Clone)]
pub struct DspSetup {
    pub config: OfdmConfig,
    pub symbol: KnownSymbol,
    pub options: ReplyOptions,
    /// `D_r` per rx slot (see [`ReplyProcessor::process`]); None: every
    /// window is timed by correlation.
    pub timing_reference: Option<Vec<usize>>,
    /// `C(r, f)`, rx slots × active subcarriers row-major: calibrated =
    /// C × measured; None: uncalibrated channels.
    pub correction: Option<Vec<Complex64>>,
    /// EMA factor across each tag's replies (None: off).
    pub ema_alpha: Option<f64>,
}

impl DspSetup {
    /// Checks the design, the options, the reference and the calibration
    /// against `antennas` rx slots.
    pub fn validate(&self, antennas: usize) -> Result<()> {
        self.config.validate()?;
        self.options.validate()?;
        if let Some(r) = &self.timing_reference {
            if r.len() != antennas || r.iter().any(|&d| d >= self.config.subcarriers) {
                return Err(Error::BadConfig(format!("timing reference {r:?} for {antennas} rx, N = {}", self.config.subcarriers)));
            }
        }
        if let Some(c) = &self.correction {
            if c.len() != antennas * self.config.active_count() {
                return Err(Error::Shape(format!(
                    "calibration has {} values for {antennas} rx × {} subcarriers",
                    c.len(),
                    self.config.active_count()
                )));
            }
        }
        if let Some(alpha) = self.ema_alpha {
            Ema::new(alpha)?;
        }
        Ok(())
    }

    /// A worker for any antenna slot (`make_worker` of [`crate::run`]),
    /// drawing its output buffers from `pool` (see [`BufferPool`]).
    pub fn worker(&self, pool: &BufferPool) -> Result<DspWorker> {
        Ok(DspWorker {
            front: AntennaFront::new(&self.config, &self.symbol, &self.options)?,
            reference: self.timing_reference.clone(),
            n: self.config.subcarriers,
            pool: pool.clone(),
        })
    }

    /// The fusion stage, returning used buffers to `pool`.
    pub fn fusion(&self, pool: &BufferPool) -> Result<DspFusion> {
        let mut processor = ReplyProcessor::new(self.config.clone(), self.symbol.clone(), self.options.clone())?;
        processor.set_timing_reference(self.timing_reference.clone())?;
        Ok(DspFusion {
            pool: pool.clone(),
            processor,
            correction: self.correction.clone(),
            ema_alpha: self.ema_alpha,
            ema: HashMap::new(),
            subcarriers: self.config.active_count(),
        })
    }
}

/// Used [`AntennaSymbols`] travelling back from fusion to the workers.
///
/// Why: each holds a copy of the antenna's window (240 kB in the thesis
/// set-up) and its sums; allocating them per reply on a worker and freeing
/// them on the fusion thread made the allocator hand out fresh pages
/// (page faults, zeroing) every time, which cost more than the DSP itself.
#[derive(Clone, Default)]
pub struct BufferPool(Arc<Mutex<Vec<AntennaSymbols>>>);

impl BufferPool {
    fn take(&self) -> AntennaSymbols {
        self.0.lock().ok().and_then(|mut p| p.pop()).unwrap_or_default()
    }

    fn give(&self, used: Vec<AntennaSymbols>) {
        if let Ok(mut p) = self.0.lock() {
            // Bounded: a stalled fusion cannot make the pool grow for ever.
            let room = 256usize.saturating_sub(p.len());
            p.extend(used.into_iter().take(room));
        }
    }
}

/// Steps 1–3a of the reply pipeline for one antenna.
pub struct DspWorker {
    front: AntennaFront,
    /// `D_r` of every rx slot.
    reference: Option<Vec<usize>>,
    n: usize,
    pool: BufferPool,
}

impl AntennaWorker for DspWorker {
    type Output = AntennaSymbols;

    fn process(&mut self, slot: usize, reply: &Reply) -> AntennaSymbols {
        // With the transmitter phase and a reference the symbol grid is
        // known: (D_r − tx_phase) mod N, no correlation timing.
        let n = self.n;
        let first_of = |phase: usize, d: usize| (d + n - phase % n) % n;
        let first = match (reply.tx_phase, self.reference.as_ref().and_then(|r| r.get(slot))) {
            (Some(phase), Some(&d)) => Some(first_of(phase, d)),
            _ => None,
        };
        let mut window = reply.windows[slot].as_slice();
        if let (Some(phase), Some(reference), Some(first)) = (reply.tx_phase, &self.reference, first) {
            // Every antenna's grid is known, so cut this window to the whole
            // symbols all antennas have: fusion then finds equal counts and
            // uses the workers' features and search shares as they are
            // (with one symbol fewer on some antenna it recomputed that
            // antenna's feature and the whole search: 0.5 ms, 5 % of replies).
            let common = reference
                .iter()
                .zip(&reply.windows)
                .map(|(&d, w)| w.len().saturating_sub(first_of(phase, d)) / n)
                .min()
                .unwrap_or(0);
            if common > 0 {
                window = &window[..(first + common * n).min(window.len())];
            }
        }
        let mut out = self.pool.take();
        self.front.process(window, first, &mut out);
        out
    }
}

/// The joint stage: detection, tag channel, calibration, EMA.
pub struct DspFusion {
    pool: BufferPool,
    processor: ReplyProcessor,
    correction: Option<Vec<Complex64>>,
    ema_alpha: Option<f64>,
    ema: HashMap<usize, Ema>,
    subcarriers: usize,
}

impl ReplyFusion<AntennaSymbols> for DspFusion {
    fn fuse(&mut self, reply: &ReplyHeader, mut antennas: Vec<AntennaSymbols>) -> std::result::Result<Vec<Option<Vec<Complex64>>>, String> {
        // The workers already placed the symbol grid; without a transmitter
        // phase the reference is neither used nor learnt.
        let estimate = self.processor.finish(&mut antennas, reply.tx_phase.filter(|_| self.processor.timing_reference().is_some()));
        self.pool.give(antennas);
        let estimate = estimate.map_err(|e| e.kind().to_string())?;
        let mut h = estimate.tag_channel;
        if let Some(c) = &self.correction {
            h.iter_mut().zip(c).for_each(|(v, c)| *v *= c);
        }
        if let Some(alpha) = self.ema_alpha {
            let ema = self.ema.entry(reply.tag).or_insert_with(|| Ema::new(alpha).expect("validated"));
            if let Ok(smoothed) = ema.update(&h) {
                // Failed antennas stay NaN: the EMA only smooths what was measured.
                h = h.iter().zip(smoothed).map(|(raw, s)| if raw.is_finite() { *s } else { *raw }).collect();
            }
        }
        Ok(h.chunks(self.subcarriers).map(|row| row.iter().all(|v| v.is_finite()).then(|| row.to_vec())).collect())
    }
}
