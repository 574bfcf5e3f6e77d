//! One reply, all rx antennas: timing → FFT → detection → edge elimination
//! → tag channel (thesis ch. 4.3 (a)–(c); Fig. 4-1).
//!
//! [`ReplyProcessor`] owns the FFT plan and every buffer, so processing a
//! reply allocates little; one processor per worker thread.

use num_complex::{Complex32, Complex64};

use crate::backscatter::{preamble_chips, Encoding};
use crate::detect::{
    combined_magnitude, combined_projection_from_sums, detect_on_grid, detect_preamble, CoarseGrid, moving_average, refine_detection, Detection, DetectionOptions, Feature,
    FeatureSums, Template,
};
use crate::error::{Error, Result};
use crate::estimate::{symbol_states, tag_channel_from_sums, ChipGrid, SymbolState, SymbolSums, TagChannel};
use crate::ofdm::{symbol_timing, ChannelMatrix, ChannelTransform, Demodulator, KnownSymbol, OfdmConfig, SymbolTiming};

/// How replies are detected and which symbols are used.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplyOptions {
    /// Tag encoding (the reader's Query `M`).
    pub encoding: Encoding,
    /// Whether the tag sends the extended pilot (Query `TRext`).
    pub trext: bool,
    /// Threshold and BLF tolerance of the preamble search.
    pub detection: DetectionOptions,
    /// Detection feature (default: coherent projection).
    pub feature: Feature,
    /// Guard on each side of a state transition, symbols (default 1):
    /// covers the detection's timing error, the tag's switching time and the
    /// delay spread (all well under one 0.2 µs symbol at 100 MHz, N = 20).
    pub guard_symbols: f64,
    /// Whether payload chips are read (decision-directed, see
    /// [`ReplyProcessor::process`]) to average more symbols than the
    /// preamble's.
    pub use_payload: bool,
    /// Payload bits to read at most after the preamble (default 17: an RN16
    /// and the dummy 1). After the reply the tag idles in one state, which
    /// must not be read as data.
    pub payload_bits: usize,
    /// How sure a payload chip decision must be: the chip's mean projection
    /// on the preamble's tag channel, normalised to ±1 for the two levels,
    /// must exceed this in magnitude (default 0.5); reading stops at the
    /// first chip that does not.
    pub decision_margin: f64,
}

impl Default for ReplyOptions {
    fn default() -> Self {
        Self {
            encoding: Encoding::Fm0,
            trext: false,
            detection: DetectionOptions::default(),
            feature: Feature::Projection,
            guard_symbols: 1.0,
            use_payload: true,
            payload_bits: 17,
            decision_margin: 0.5,
        }
    }
}

impl ReplyOptions {
    /// Checks the domains (guard ≥ 0, margin in (0, 1), encoding, detection).
    pub fn validate(&self) -> Result<()> {
        self.encoding.validate()?;
        if !(self.guard_symbols >= 0.0 && self.guard_symbols.is_finite()) {
            return Err(Error::BadConfig(format!("guard_symbols must be ≥ 0, got {}", self.guard_symbols)));
        }
        if !(self.decision_margin > 0.0 && self.decision_margin < 1.0) {
            return Err(Error::BadConfig(format!("decision_margin must be in (0, 1), got {}", self.decision_margin)));
        }
        let d = &self.detection;
        if !(d.threshold > 0.0 && d.threshold <= 1.0) {
            return Err(Error::BadConfig(format!("threshold must be in (0, 1], got {}", d.threshold)));
        }
        if !(d.blf_tolerance >= 0.0 && d.blf_tolerance < 0.5) {
            return Err(Error::BadConfig(format!("blf_tolerance must be in [0, 0.5), got {}", d.blf_tolerance)));
        }
        Ok(())
    }
}

/// How many symbols of one antenna ended in each state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StateCounts {
    /// Used, reflective (level 1).
    pub high: usize,
    /// Used, non-reflective (level 0).
    pub low: usize,
    /// Discarded: within a guard of a transition (edge-flip elimination).
    pub edge: usize,
    /// Not in the reply.
    pub outside: usize,
    /// Non-finite samples.
    pub invalid: usize,
}

impl StateCounts {
    fn of(states: &[SymbolState]) -> Self {
        let mut c = Self::default();
        for s in states {
            match s {
                SymbolState::High => c.high += 1,
                SymbolState::Low => c.low += 1,
                SymbolState::Edge => c.edge += 1,
                SymbolState::Outside => c.outside += 1,
                SymbolState::Invalid => c.invalid += 1,
            }
        }
        c
    }
}

/// The outcome of one reply over all rx antennas.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplyEstimate {
    /// Receive antennas (rows), in the order given.
    pub antennas: usize,
    /// Active subcarriers (columns), ascending frequency.
    pub subcarriers: usize,
    /// Whole symbols processed per antenna (the shortest antenna's).
    pub symbols: usize,
    /// Uncalibrated tag channel, `antennas × subcarriers` row-major; NaN in
    /// the rows of failed antennas.
    pub tag_channel: Vec<Complex64>,
    /// Variance of each entry of `tag_channel` (NaN for failed antennas).
    pub variance: Vec<f64>,
    /// Why an antenna has no estimate (`None` where it has one).
    pub antenna_errors: Vec<Option<Error>>,
    /// The preamble detection (start, chip length, score, per-antenna ρ).
    pub detection: Detection,
    /// Estimated tag BLF, Hz.
    pub blf_hz: f64,
    /// Start of the preamble's first chip in window samples (on the first
    /// antenna that worked): `first_sample + start_symbol · N`.
    pub start_sample: f64,
    /// First sample of the first whole symbol used per antenna.
    pub first_samples: Vec<usize>,
    /// The correlation timing per antenna (`None` where it failed).
    pub timings: Vec<Option<SymbolTiming>>,
    /// Payload chips read after the preamble.
    pub payload_chips: usize,
    /// Symbol states per antenna, `antennas × symbols` row-major
    /// (all [`SymbolState::Invalid`] for failed antennas).
    pub states: Vec<SymbolState>,
    /// State counts per antenna.
    pub counts: Vec<StateCounts>,
}

/// One antenna's share of a reply (steps 1–3a of
/// [`ReplyProcessor::process`]): symbol timing, the symbols' time-domain
/// prefix sums, the smoothed detection feature and its share of the coarse
/// preamble search — the expensive, independent part, so that a
/// real-time runtime can run one worker per rx antenna (thesis §6) and
/// leave only the joint preamble search and the tag channel to
/// [`ReplyProcessor::finish`].
#[derive(Debug, Clone, Default)]
pub struct AntennaSymbols {
    /// The whole symbols (time domain) with prefix sums over symbols: the
    /// fusion stage sums runs of symbols from these and demodulates only
    /// the sums (see [`SymbolSums`]).
    pub symbol_sums: SymbolSums,
    /// Running sums of the smoothed detection feature (valid when
    /// `feature_error` is None).
    pub sums: FeatureSums,
    /// First sample of the first whole symbol used.
    pub first_sample: usize,
    /// The correlation timing, when it was computed (no known first sample).
    pub timing: Option<SymbolTiming>,
    /// Why the antenna has no channel (timing or demodulation failed).
    pub error: Option<Error>,
    /// Why the antenna cannot take part in the detection.
    pub feature_error: Option<Error>,
    /// This antenna's `ρ²` on the stage-1 detection grid (see
    /// [`CoarseGrid`]), for a window of `coarse_symbols` symbols.
    pub coarse: Vec<f64>,
    pub coarse_symbols: usize,
}

/// Steps 1–3a for one antenna with its FFT plan and buffers (one per worker).
pub struct AntennaFront {
    symbol: KnownSymbol,
    feature_kind: Feature,
    template: Template,
    nominal_chip_symbols: f64,
    blf_tolerance: f64,
    /// The stage-1 grid of the last window length seen (windows of one
    /// helper all have the same length, so it is built once).
    grid: Option<CoarseGrid>,
    /// The linear demodulation map (sums, projection filter).
    transform: ChannelTransform,
    /// Per-symbol demodulation, only for the magnitude feature (it is not
    /// linear in the samples).
    demodulator: Demodulator,
    matrix: ChannelMatrix,
    /// Projection block and smoothing width, symbols (a quarter and an
    /// eighth of a nominal chip: see [`ReplyProcessor::process`]).
    block: usize,
    smoothing: usize,
    feature: Vec<f64>,
    smoothed: Vec<f64>,
}

impl AntennaFront {
    pub fn new(config: &OfdmConfig, symbol: &KnownSymbol, options: &ReplyOptions) -> Result<Self> {
        config.validate()?;
        options.validate()?;
        let chip_nominal = config.chip_symbols();
        Ok(Self {
            symbol: symbol.clone(),
            feature_kind: options.feature,
            template: Template::new(preamble_chips(options.encoding, options.trext)?)?,
            nominal_chip_symbols: chip_nominal,
            blf_tolerance: options.detection.blf_tolerance,
            grid: None,
            transform: ChannelTransform::new(config, symbol)?,
            demodulator: Demodulator::new(config, symbol)?,
            matrix: ChannelMatrix::default(),
            block: ((chip_nominal / 4.0).floor() as usize).max(1),
            smoothing: ((chip_nominal / 8.0).floor() as usize).max(1),
            feature: Vec::new(),
            smoothed: Vec::new(),
        })
    }

    /// Processes one antenna's window into `out` (buffers reused). With
    /// `first_sample` (from [`ReplyProcessor::first_sample`]) the
    /// correlation timing is skipped: the reference fixes the symbol grid.
    pub fn process(&mut self, window: &[Complex32], first_sample: Option<usize>, out: &mut AntennaSymbols) {
        out.error = None;
        out.feature_error = None;
        out.timing = None;
        let first = match first_sample {
            Some(first) => first,
            None => match symbol_timing(window, &self.symbol) {
                Ok(t) => {
                    out.timing = Some(t);
                    t.first_sample
                }
                Err(e) => {
                    out.error = Some(e);
                    out.first_sample = 0;
                    return;
                }
            },
        };
        out.first_sample = first;
        if let Err(e) = out.symbol_sums.reset(window, first, self.transform.symbol_len()) {
            out.error = Some(e);
            return;
        }
        self.feature(out);
    }

    /// The smoothed detection feature of `out`'s symbols into `out.sums`.
    fn feature(&mut self, out: &mut AntennaSymbols) {
        let sums = &out.symbol_sums;
        match self.feature_kind {
            Feature::CombinedMagnitude => {
                // Σ_f |H(f, n)| needs every symbol demodulated.
                let _ = self.demodulator.demodulate(&sums.samples, 0, &mut self.matrix);
                self.matrix.valid.copy_from_slice(&sums.valid);
                combined_magnitude(&self.matrix, &mut self.feature)
            }
            Feature::Projection => combined_projection_from_sums(sums, &mut self.transform, self.block, &mut self.feature),
        }
        moving_average(&self.feature, self.smoothing, &mut self.smoothed);
        out.feature_error = out.sums.reset(&self.smoothed).err();
        out.coarse.clear();
        out.coarse_symbols = 0;
        if out.feature_error.is_none() {
            let symbols = out.sums.len();
            self.ensure_grid(symbols);
            let grid = self.grid.as_ref().expect("just built");
            out.coarse.resize(grid.len(), 0.0);
            grid.add_scores(&out.sums, &self.template, &mut out.coarse);
            out.coarse_symbols = symbols;
        }
    }

    /// The stage-1 search grid for features of `symbols` values, built once
    /// per window length (the fronts and the joint stage share it).
    fn ensure_grid(&mut self, symbols: usize) {
        if self.grid.as_ref().is_none_or(|g| g.symbols != symbols) {
            self.grid = Some(CoarseGrid::new(symbols, self.template.len(), self.nominal_chip_symbols, self.blf_tolerance));
        }
    }
}

/// Processes reply windows of `R` rx antennas with buffers reused across
/// calls (one per worker).
pub struct ReplyProcessor {
    config: OfdmConfig,
    options: ReplyOptions,
    front: AntennaFront,
    /// Demodulates the sums of runs of symbols (tag channels, payload chips).
    transform: ChannelTransform,
    template: Template,
    timing_reference: Option<Vec<usize>>,
    antennas: Vec<AntennaSymbols>,
    states: Vec<SymbolState>,
}

impl ReplyProcessor {
    /// A processor for one helper configuration, its known symbol and the
    /// reply options. Validates all three.
    pub fn new(config: OfdmConfig, symbol: KnownSymbol, options: ReplyOptions) -> Result<Self> {
        config.validate()?;
        options.validate()?;
        let front = AntennaFront::new(&config, &symbol, &options)?;
        let transform = ChannelTransform::new(&config, &symbol)?;
        let template = Template::new(preamble_chips(options.encoding, options.trext)?)?;
        Ok(Self {
            config,
            options,
            front,
            transform,
            template,
            timing_reference: None,
            antennas: Vec::new(),
            states: Vec::new(),
        })
    }

    /// The OFDM configuration.
    pub fn config(&self) -> &OfdmConfig {
        &self.config
    }

    /// The known OFDM symbol.
    pub fn symbol(&self) -> &KnownSymbol {
        &self.front.symbol
    }

    /// The reply options.
    pub fn options(&self) -> &ReplyOptions {
        &self.options
    }

    /// Per-rx timing reference `D_r = (first_sample + tx_phase) mod N`
    /// (see [`ReplyProcessor::process`]), once known.
    pub fn timing_reference(&self) -> Option<&[usize]> {
        self.timing_reference.as_deref()
    }

    /// Sets (or clears) the timing reference, e.g. the one learnt on the
    /// calibration recording. Every entry must be `< N`.
    pub fn set_timing_reference(&mut self, reference: Option<Vec<usize>>) -> Result<()> {
        if let Some(r) = &reference {
            if let Some(bad) = r.iter().find(|&&d| d >= self.config.subcarriers) {
                return Err(Error::BadConfig(format!("timing reference {bad} ≥ N = {}", self.config.subcarriers)));
            }
        }
        self.timing_reference = reference;
        Ok(())
    }

    /// Estimates the tag channel of one reply from its windows, one per rx
    /// antenna (raw baseband samples, any equal or unequal lengths).
    ///
    /// 1. Symbol timing per antenna. When `tx_phase` is given — the index of
    ///    the window's first sample in the transmitter's stream, modulo `N`,
    ///    known exactly because tx and rx share one clock — and a timing
    ///    reference `D_r` is known, the first symbol starts at
    ///    `(D_r − tx_phase) mod N`; otherwise at the correlation peak
    ///    ([`symbol_timing`], ch. 4.3), and with `tx_phase` the reference is
    ///    learnt from it. Why: the estimated channel carries a linear phase
    ///    `exp(j2π f (first_sample + tx_phase)/B)`; the reference keeps it
    ///    identical in every window even if noise or a hardware delay near
    ///    half a sample would make the peak hop by one sample between
    ///    windows (a 3 m jump of the apparent path at 100 MHz).
    /// 2. The whole symbols with their prefix sums ([`SymbolSums`]): the
    ///    demodulation `H = FFT(y)/(√N X)` is linear, so later steps
    ///    demodulate sums of runs of symbols ([`ChannelTransform`]) rather
    ///    than every symbol ([`Demodulator`] is used only for the
    ///    magnitude feature).
    /// 3. Detection feature per antenna, smoothed over an eighth of a chip
    ///    ([`moving_average`]), and the joint preamble search
    ///    ([`detect_preamble`]).
    /// 4. Edge-flip elimination on the preamble chips, tag channel per
    ///    antenna ([`symbol_states`], [`tag_channel_from_sums`]).
    /// 5. With `use_payload`: payload chips are read one by one — the
    ///    chip's clean symbols projected on the preamble's tag channel around
    ///    its midpoint, summed over antennas, normalised so that the two
    ///    levels give ±1 — while the decision is clear (`decision_margin`),
    ///    the chip lies wholly in the window and fewer than `payload_bits`
    ///    bits were read; then the alignment is refined on preamble +
    ///    payload ([`refine_detection`]) and states and tag channels are
    ///    recomputed over both. Transitions are only where decided levels
    ///    change, so only their neighbours are discarded.
    ///
    /// Antenna-level failures (all-NaN window, no clean symbol) leave that
    /// antenna's row NaN and its error in `antenna_errors`. Errors for the
    /// whole reply: [`Error::Shape`] (no window, reference of the wrong
    /// length), every antenna failing (that antenna's error), and the
    /// detection's ([`Error::NoPreamble`], [`Error::TooShort`]).
    pub fn process(&mut self, windows: &[&[Complex32]], tx_phase: Option<usize>) -> Result<ReplyEstimate> {
        let r = windows.len();
        if r == 0 {
            return Err(Error::Shape("no rx window given".into()));
        }
        self.check_reference(r, tx_phase)?;
        let mut antennas = std::mem::take(&mut self.antennas);
        antennas.resize_with(r, AntennaSymbols::default);
        for (a, (window, out)) in windows.iter().zip(antennas.iter_mut()).enumerate() {
            let first = self.first_sample(a, tx_phase);
            self.front.process(window, first, out);
        }
        let result = self.finish(&mut antennas, tx_phase);
        self.antennas = antennas;
        result
    }

    /// Where antenna `slot`'s first whole symbol starts when the window's
    /// transmitter phase is `tx_phase` and a timing reference is known:
    /// `(D_r − tx_phase) mod N`; None (→ correlation timing) otherwise.
    /// What a per-antenna worker passes to [`AntennaFront::process`].
    pub fn first_sample(&self, slot: usize, tx_phase: Option<usize>) -> Option<usize> {
        let n = self.config.subcarriers;
        match (tx_phase, &self.timing_reference) {
            (Some(phase), Some(reference)) => reference.get(slot).map(|&d| (d + n - phase % n) % n),
            _ => None,
        }
    }

    fn check_reference(&self, r: usize, tx_phase: Option<usize>) -> Result<()> {
        if let Some(reference) = &self.timing_reference {
            if tx_phase.is_some() && reference.len() != r {
                return Err(Error::Shape(format!("timing reference has {} antennas, reply has {r}", reference.len())));
            }
        }
        Ok(())
    }

    /// Steps 3 (joint preamble search) to 5 of [`ReplyProcessor::process`]
    /// on the per-antenna results of [`AntennaFront::process`] (one per rx
    /// antenna, in order; computed by this processor or by per-antenna
    /// workers). With `tx_phase` and no timing reference yet, the reference
    /// is learnt from the antennas' correlation timing when all succeeded.
    /// The antennas' matrices may be truncated to a common symbol count.
    pub fn finish(&mut self, antennas: &mut [AntennaSymbols], tx_phase: Option<usize>) -> Result<ReplyEstimate> {
        let r = antennas.len();
        let n = self.config.subcarriers;
        let f_count = self.config.active_count();
        if r == 0 {
            return Err(Error::Shape("no rx window given".into()));
        }
        self.check_reference(r, tx_phase)?;
        let mut errors: Vec<Option<Error>> = antennas.iter().map(|a| a.error.clone()).collect();
        let timings: Vec<Option<SymbolTiming>> = antennas.iter().map(|a| a.timing).collect();
        let first_samples: Vec<usize> = antennas.iter().map(|a| a.first_sample).collect();
        let good: Vec<usize> = (0..r).filter(|&a| errors[a].is_none()).collect();
        if good.is_empty() {
            return Err(errors.into_iter().flatten().next().unwrap_or(Error::Shape("no antenna".into())));
        }
        if let (Some(phase), None) = (tx_phase, &self.timing_reference) {
            if good.len() == r {
                self.timing_reference = Some(first_samples.iter().map(|&m| (m + phase) % n).collect());
            }
        }
        let symbols = good.iter().map(|&a| antennas[a].symbol_sums.symbols).min().unwrap_or(0);
        for &a in &good {
            if antennas[a].symbol_sums.symbols != symbols {
                // Unequal windows: truncate and recompute the feature on the
                // common span (row-major: keeps the first `symbols` rows).
                antennas[a].symbol_sums.truncate(symbols);
                self.front.feature(&mut antennas[a]);
            }
        }
        for &a in &good {
            if let Some(e) = &antennas[a].feature_error {
                errors[a] = Some(e.clone());
            }
        }
        let detecting: Vec<usize> = good.iter().copied().filter(|&a| antennas[a].feature_error.is_none()).collect();
        if detecting.is_empty() {
            return Err(errors.into_iter().flatten().next().unwrap_or(Error::Shape("no antenna".into())));
        }
        let chip_nominal = self.config.chip_symbols();
        let features: Vec<&FeatureSums> = detecting.iter().map(|&a| &antennas[a].sums).collect();
        // Stage 1 of the search was done per antenna (by the fronts) when all
        // windows had the same length; the shares add up.
        let precomputed = detecting.iter().all(|&a| antennas[a].coarse_symbols == symbols && !antennas[a].coarse.is_empty());
        let mut detection = if precomputed {
            // The front was built from the same options: its grid is this one.
            self.front.ensure_grid(symbols);
            let grid = self.front.grid.as_ref().expect("just built");
            let mut summed = vec![0.0; grid.len()];
            for &a in &detecting {
                summed.iter_mut().zip(&antennas[a].coarse).for_each(|(s, c)| *s += c);
            }
            detect_on_grid(&features, &self.template, chip_nominal, &self.options.detection, &grid, &summed)?
        } else {
            detect_preamble(&features, &self.template, chip_nominal, &self.options.detection)?
        };

        // 4: edge elimination and tag channel on the preamble.
        let k = self.template.len();
        let mut grid = ChipGrid {
            start_symbol: detection.start_symbol,
            chip_symbols: detection.chip_symbols,
            guard_symbols: self.options.guard_symbols,
            drift_per_chip: detection.chip_symbols * detection.scale_uncertainty,
            reference_chip: k as f64 / 2.0,
        };
        let mut levels: Vec<Option<u8>> = self.template.levels.iter().map(|&l| Some(l)).collect();
        let mut estimates: Vec<Option<TagChannel>> = vec![None; r];
        for &a in &detecting {
            symbol_states(&grid, &levels, &antennas[a].symbol_sums.valid, &mut self.states);
            match tag_channel_from_sums(&antennas[a].symbol_sums, &self.states, &mut self.transform) {
                Ok(t) => estimates[a] = Some(t),
                Err(e) => errors[a] = Some(e),
            }
        }

        // 5: decision-directed payload chips.
        let mut payload_chips = 0;
        if self.options.use_payload && estimates.iter().any(|e| e.is_some()) {
            let limit = self.options.payload_bits * self.options.encoding.chips_per_bit();
            for i in k..k + limit {
                match self.decide_chip(antennas, &grid, i, symbols, &estimates) {
                    Some(level) => levels.push(Some(level)),
                    None => break,
                }
                payload_chips += 1;
            }
            if payload_chips > 0 {
                // Re-align on preamble + payload: many more transitions over a
                // longer span pin the BLF down, so the payload's guards stay
                // narrow. Score and correlations stay the preamble's.
                let extended = Template::new(levels.iter().map(|l| l.unwrap_or(0)).collect())?;
                // ±4 steps must cover the preamble's own scale uncertainty.
                let step = (1.0 / (16.0 * extended.len() as f64)).max(detection.scale_uncertainty / 4.0);
                let refined = refine_detection(
                    &features,
                    &extended,
                    chip_nominal,
                    detection.start_symbol,
                    detection.blf_scale,
                    step,
                );
                detection.start_symbol = refined.start_symbol;
                detection.chip_symbols = refined.chip_symbols;
                detection.blf_scale = refined.blf_scale;
                detection.scale_uncertainty = step / 2.0;
                grid = ChipGrid {
                    start_symbol: detection.start_symbol,
                    chip_symbols: detection.chip_symbols,
                    drift_per_chip: detection.chip_symbols * detection.scale_uncertainty,
                    reference_chip: extended.len() as f64 / 2.0,
                    ..grid
                };
                for &a in &detecting {
                    if estimates[a].is_none() {
                        continue;
                    }
                    symbol_states(&grid, &levels, &antennas[a].symbol_sums.valid, &mut self.states);
                    match tag_channel_from_sums(&antennas[a].symbol_sums, &self.states, &mut self.transform) {
                        Ok(t) => estimates[a] = Some(t),
                        Err(e) => {
                            errors[a] = Some(e);
                            estimates[a] = None;
                        }
                    }
                }
            }
        }

        // Collect the outcome.
        let nan = Complex64::new(f64::NAN, f64::NAN);
        let mut channel = vec![nan; r * f_count];
        let mut variance = vec![f64::NAN; r * f_count];
        let mut states = vec![SymbolState::Invalid; r * symbols];
        let mut counts = vec![StateCounts::default(); r];
        for a in 0..r {
            let Some(t) = &estimates[a] else {
                counts[a] = StateCounts { invalid: symbols, ..Default::default() };
                continue;
            };
            channel[a * f_count..(a + 1) * f_count].copy_from_slice(&t.h);
            variance[a * f_count..(a + 1) * f_count].copy_from_slice(&t.variance);
            symbol_states(&grid, &levels, &antennas[a].symbol_sums.valid, &mut self.states);
            states[a * symbols..(a + 1) * symbols].copy_from_slice(&self.states);
            counts[a] = StateCounts::of(&self.states);
        }
        if estimates.iter().all(|e| e.is_none()) {
            return Err(errors.into_iter().flatten().next().unwrap_or(Error::NoCleanSymbols { high: 0, low: 0 }));
        }
        let reference_antenna = good[0];
        Ok(ReplyEstimate {
            antennas: r,
            subcarriers: f_count,
            symbols,
            tag_channel: channel,
            variance,
            antenna_errors: errors,
            blf_hz: self.config.blf_hz * detection.blf_scale,
            start_sample: first_samples[reference_antenna] as f64 + detection.start_symbol * n as f64,
            detection,
            first_samples,
            timings,
            payload_chips,
            states,
            counts,
        })
    }

    /// Reads payload chip `i`: `Some(level)` when its clean symbols decide
    /// clearly, `None` to stop (see [`ReplyProcessor::process`], step 5).
    fn decide_chip(
        &mut self,
        antennas: &[AntennaSymbols],
        grid: &ChipGrid,
        i: usize,
        symbols: usize,
        estimates: &[Option<TagChannel>],
    ) -> Option<u8> {
        let end = grid.boundary(i + 1);
        if end > symbols as f64 {
            return None;
        }
        let from = (grid.boundary(i) + grid.guard(i)).ceil().max(0.0) as usize;
        let to = (end - grid.guard(i + 1) - 1.0).floor() + 1.0; // n + 1 ≤ end − guard
        if to <= from as f64 {
            return None;
        }
        let to = to as usize;
        let (mut numerator, mut denominator) = (0.0, 0.0);
        let zero = Complex64::new(0.0, 0.0);
        let mut time = Vec::new();
        let mut channel = vec![zero; self.transform.subcarriers()];
        for (a, estimate) in estimates.iter().enumerate() {
            let Some(t) = estimate else { continue };
            // Σ_n (H_n − m)·d̄ over the chip's clean symbols: the chip's
            // samples summed (Σ x + k r), demodulated once, minus k m.
            let sums = &antennas[a].symbol_sums;
            time.clear();
            time.resize(sums.n, zero);
            let k = sums.add_interval(from, to, &mut time, None) as f64;
            if k == 0.0 {
                continue;
            }
            time.iter_mut().zip(&sums.reference).for_each(|(x, r)| *x += r * k);
            self.transform.apply(&time, &mut channel);
            let energy: f64 = t.h.iter().map(|v| v.norm_sqr()).sum();
            let projection: f64 =
                channel.iter().zip(&t.midpoint).zip(&t.h).map(|((h, m), d)| ((h - m * k) * d.conj()).re).sum();
            numerator += projection;
            denominator += k * energy / 2.0;
        }
        if denominator <= 0.0 {
            return None;
        }
        let z = numerator / denominator;
        if z >= self.options.decision_margin {
            Some(1)
        } else if z <= -self.options.decision_margin {
            Some(0)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backscatter::reply_chips;
    use std::f64::consts::TAU;

    /// A synthetic reply without noise: every rx antenna hears the
    /// transmitter's periodic OFDM symbol through a leakage channel and,
    /// while the tag reflects (FM0 chips of 12.5 µs from 25 µs on), through
    /// the tag channel `tag(a, k)` (FFT bin `k`, FFT timing at the
    /// transmitter's symbol boundary). The window's first sample is
    /// `tx_phase` into the transmitter's stream.
    struct Synthetic {
        config: OfdmConfig,
        symbol: KnownSymbol,
        tx_phase: usize,
        antennas: usize,
    }

    impl Synthetic {
        fn new() -> Self {
            let config = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
            Self { config, symbol: KnownSymbol::generate(20, 17).unwrap(), tx_phase: 7, antennas: 3 }
        }

        fn tag(&self, a: usize, k: usize) -> Complex64 {
            Complex64::from_polar(0.02 * (1.0 + 0.3 * a as f64), 0.9 * a as f64 + 0.35 * k as f64)
        }

        fn leak(&self, a: usize, k: usize) -> Complex64 {
            Complex64::from_polar(1.0 + 0.1 * a as f64, -0.2 * k as f64 + a as f64)
        }

        /// One period of the received symbol through `spectrum` (unitary inverse DFT).
        fn periodic(&self, spectrum: impl Fn(usize) -> Complex64) -> Vec<Complex64> {
            let n = self.config.subcarriers;
            (0..n)
                .map(|t| {
                    (0..n).map(|k| self.symbol.frequency[k] * spectrum(k) * Complex64::from_polar(1.0, TAU * (k * t) as f64 / n as f64)).sum::<Complex64>()
                        / (n as f64).sqrt()
                })
                .collect()
        }

        fn windows(&self) -> Vec<Vec<Complex32>> {
            let chips = reply_chips(Encoding::Fm0, false, &[1, 0, 1, 1, 0, 0, 1, 0, 1, 1, 1, 0, 0, 1, 0, 1]).unwrap();
            let (n, samples, chip, start) = (self.config.subcarriers, 30_000, 1250.0, 2500.0);
            let level = |i: usize| {
                let c = ((i as f64 - start) / chip).floor();
                if c < 0.0 || c >= chips.len() as f64 { 0.0 } else { chips[c as usize] as f64 }
            };
            (0..self.antennas)
                .map(|a| {
                    let leak = self.periodic(|k| self.leak(a, k));
                    let tag = self.periodic(|k| self.tag(a, k));
                    (0..samples)
                        .map(|i| {
                            let p = (i + self.tx_phase) % n;
                            let v = leak[p] + tag[p] * level(i);
                            Complex32::new(v.re as f32, v.im as f32)
                        })
                        .collect()
                })
                .collect()
        }

        /// The estimate with the timing's linear phase `exp(j2π k' D / N)`,
        /// `D = first_sample + tx_phase`, removed: comparable with `tag`.
        fn untimed(&self, e: &ReplyEstimate) -> Vec<Complex64> {
            let n = self.config.subcarriers as f64;
            let bins = self.config.signed_bins();
            let f = e.subcarriers;
            e.tag_channel
                .iter()
                .enumerate()
                .map(|(i, h)| {
                    let d = (e.first_samples[i / f] + self.tx_phase) as f64;
                    h * Complex64::from_polar(1.0, -TAU * bins[i % f] as f64 * d / n)
                })
                .collect()
        }

        fn truth(&self) -> Vec<Complex64> {
            let bins = self.config.active_bins();
            (0..self.antennas).flat_map(|a| bins.iter().map(move |&k| self.tag(a, k))).collect()
        }
    }

    fn refs(windows: &[Vec<Complex32>]) -> Vec<&[Complex32]> {
        windows.iter().map(|w| w.as_slice()).collect()
    }

    #[test]
    fn a_noiseless_reply_gives_its_tag_channel() {
        let s = Synthetic::new();
        let windows = s.windows();
        let mut p = ReplyProcessor::new(s.config.clone(), s.symbol.clone(), ReplyOptions::default()).unwrap();
        let e = p.process(&refs(&windows), None).unwrap();
        assert_eq!((e.antennas, e.subcarriers), (3, s.config.active_count()));
        assert!(e.antenna_errors.iter().all(Option::is_none), "{:?}", e.antenna_errors);
        assert!((e.start_sample - 2500.0).abs() < 20.0, "start {}", e.start_sample);
        assert!((e.blf_hz / 40e3 - 1.0).abs() < 0.01, "BLF {}", e.blf_hz);
        let worst = s.untimed(&e).iter().zip(s.truth()).map(|(g, t)| (g - t).norm() / t.norm()).fold(0.0, f64::max);
        // f32 samples with the leakage 34 dB above the tag.
        assert!(worst < 1e-3, "worst relative error {worst}");
        for (a, c) in e.counts.iter().enumerate() {
            assert_eq!(c.high + c.low + c.edge + c.outside + c.invalid, e.symbols, "antenna {a}");
            assert!(c.high > 0 && c.low > 0 && c.edge > 0, "antenna {a}: {c:?}");
        }
    }

    /// The runtime's split, per-antenna fronts and one joint finish, is
    /// the same computation as `process`.
    #[test]
    fn fronts_then_finish_equal_process() {
        let s = Synthetic::new();
        let windows = s.windows();
        let options = ReplyOptions::default();
        let mut whole = ReplyProcessor::new(s.config.clone(), s.symbol.clone(), options.clone()).unwrap();
        let expected = whole.process(&refs(&windows), Some(s.tx_phase)).unwrap();
        let mut joint = ReplyProcessor::new(s.config.clone(), s.symbol.clone(), options.clone()).unwrap();
        let mut front = AntennaFront::new(&s.config, &s.symbol, &options).unwrap();
        let mut antennas: Vec<AntennaSymbols> = (0..windows.len()).map(|_| AntennaSymbols::default()).collect();
        for (a, (w, out)) in windows.iter().zip(antennas.iter_mut()).enumerate() {
            front.process(w, joint.first_sample(a, Some(s.tx_phase)), out);
        }
        let got = joint.finish(&mut antennas, Some(s.tx_phase)).unwrap();
        assert_eq!(got, expected);
        assert_eq!(joint.timing_reference(), whole.timing_reference());
    }

    /// With the transmitter phase given, the first reply teaches the timing
    /// reference D_r = (first_sample + tx_phase) mod N, and the next reply
    /// is cut on it without the correlation timing.
    #[test]
    fn the_timing_reference_is_learnt_then_used() {
        let s = Synthetic::new();
        let windows = s.windows();
        let n = s.config.subcarriers;
        let mut p = ReplyProcessor::new(s.config.clone(), s.symbol.clone(), ReplyOptions::default()).unwrap();
        assert!(p.timing_reference().is_none());
        let first = p.process(&refs(&windows), Some(s.tx_phase)).unwrap();
        let reference: Vec<usize> = first.first_samples.iter().map(|&m| (m + s.tx_phase) % n).collect();
        assert_eq!(p.timing_reference(), Some(reference.as_slice()));
        assert!(first.timings.iter().all(Option::is_some));
        let second = p.process(&refs(&windows), Some(s.tx_phase)).unwrap();
        assert!(second.timings.iter().all(Option::is_none), "the reference replaces the correlation");
        assert_eq!(second.first_samples, first.first_samples);
        assert_eq!(second.tag_channel, first.tag_channel);
        assert!(p.set_timing_reference(Some(vec![n; 3])).is_err());
        assert!(matches!(p.process(&refs(&windows[..2]), Some(s.tx_phase)), Err(Error::Shape(_))));
    }

    #[test]
    fn options_outside_their_domains_are_rejected() {
        let bad = [
            ReplyOptions { guard_symbols: -1.0, ..Default::default() },
            ReplyOptions { decision_margin: 1.0, ..Default::default() },
            ReplyOptions { detection: DetectionOptions { threshold: 0.0, ..Default::default() }, ..Default::default() },
        ];
        for options in bad {
            assert!(matches!(options.validate(), Err(Error::BadConfig(_))), "{options:?}");
        }
        let s = Synthetic::new();
        assert!(ReplyProcessor::new(s.config, s.symbol, ReplyOptions { guard_symbols: f64::NAN, ..Default::default() }).is_err());
        assert!(matches!(ReplyProcessor::new(Synthetic::new().config, Synthetic::new().symbol, ReplyOptions::default()).unwrap().process(&[], None), Err(Error::Shape(_))));
    }
}
