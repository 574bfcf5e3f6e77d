//! One sensing epoch's whole chain (docs/marvel.md sections 5 and 7): two
//! excitation channels x four tags x `M` receive antennas, one chirp each.
//!
//! Order, and why:
//! 1. peaks of all `2 x 4 x M` chirps ([`PeakFinder`], step 1);
//! 2. angle per tag by MUSIC on the calibrated centre phases (step 5). The
//!    epoch's phase ramps are common to the antennas of a (channel, tag), so
//!    the angle needs no Doppler correction — and it is the direction that
//!    the translational Doppler prediction then uses;
//! 3. Doppler and CFO (step 2): CFO `eps s_k`; translational shift
//!    `-(2 F/c0) u . v_gear` from the fused velocity (Marvel) or 0 (the
//!    Doppler-blind mu-locate baseline); rotational shift per tag from the
//!    pair half difference (eq. 7) averaged over the antennas;
//! 4. channel phases at the epoch's reference time (eq. 3, step 3);
//! 5. chirp-timing range from the pair means (eq. 2), and the phase range
//!    (step 4);
//! 6. yaw from the pair differences (eqs. 7-8, step 6) when the attitude
//!    and the gyroscope's rate are given.
//!
//! **Range and the frequency plan.** The received carriers are
//! `F_jk = f_j + s_k/2`: two clusters (902.6-904.1 and 928.5-930.0 MHz for
//! channels 0 and 12). The phases of *different tags* differ by their
//! positions on the gear (up to `2 D` = 1.3 m of path, several
//! wavelengths) and by each tag's clock phase `2 pi eps s_k t`, so only the
//! two channels of the *same* tag are coherent, and two frequencies 25.9
//! MHz apart give a fringe of period `c0 / (2 x 25.9 MHz)` = 5.8 m: the
//! phase range is precise (cm) but ambiguous. The chirp timing (the pair
//! means' `-(BW/T) tau`) gives an unambiguous but coarse range (metres at
//! -10 dB); the default combines them: the fringe peak nearest the timing
//! range ([`RangeWindow::AroundTiming`], searched over +- one fringe). [`RangeCoherence`]
//! selects which phases are treated as coherent; the paper's reading (all
//! eight per antenna, [`RangeCoherence::AcrossTags`], whole interval) is
//! available and is exact only when the tags' geometric and clock phases
//! are removed, which this step cannot do.
//!
//! Sample layout: one flat slice, C order of `(2 channels, 4 tags, M
//! antennas, N samples)`, index `((j * 4 + k) * M + m) * N + n`; each chirp
//! starts at its own first sample (`t_j = chirp_starts_s[j]`).

use super::chirp::ChirpConfig;
use super::doppler::{cfo_hz, delay_from_frequency_s, pair_half_difference, pair_mean, translational_doppler_hz};
use super::geometry::{add, cross, dot, mat_vec, normalize, split_yaw, Mat3, Vec3};
use super::heading::{solve_yaw, HeadingConfig, HeadingEstimate, PairObservation, YawGeometry};
use super::music::{combine_angles, music, AngleCombine, ArrayGeometry, MusicConfig, MusicEstimate};
use super::peak::{Peak, PeakFinder, PeakOptions, Sample};
use super::phase::{channel_phase, PhaseCorrection};
use super::range::{estimate_range, group_deviations_m, PhaseGroup, RangeConfig, RangeEstimate, RangeSelect};
use crate::error::{Error, Result};
use crate::SPEED_OF_LIGHT;

/// Excitation channels per epoch.
pub const CHANNELS: usize = 2;
/// Tags on the drone.
pub const TAGS: usize = 4;

/// Which channel phases the range profile adds coherently.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RangeCoherence {
    /// The paper's reading: the 8 phases of an antenna (2 channels x 4
    /// tags) in one group. Needs the tags' clock phases removed
    /// (`Corrections::epoch_time_s` with an exact `eps`) and is biased by
    /// the tags' positions on the gear.
    AcrossTags,
    /// One group per (antenna, tag): the tag's two channels. Free of tag
    /// geometry and clock phase; a fringe of period `c0 / (2 (f_1 - f_0))`.
    #[default]
    PerTag,
    /// One group per antenna of the 4 pair sums `theta_a + theta_b` at the
    /// virtual carriers `F_a + F_b`: an opposing pair's geometric offsets
    /// cancel (to first order), the pairs' clock phases do not.
    PairSums,
}

/// Where the phase range is searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RangeWindow {
    /// The whole `RangeConfig` interval (the paper's first-path search).
    Full,
    /// `timing range +- half_width_m` (m), within the `RangeConfig` interval,
    /// and of the profile's peaks above the threshold the one nearest to
    /// the timing range ([`RangeSelect::NearestTo`]): the timing picks the
    /// fringe, the phases place it.
    AroundTiming { half_width_m: f64 },
}

/// One epoch's layout and options.
#[derive(Debug, Clone, PartialEq)]
pub struct EpochConfig {
    pub chirp: ChirpConfig,
    /// Excitation channel centres `f_j`, Hz (docs/marvel.md section 5).
    pub channels_hz: [f64; CHANNELS],
    /// Start of each channel's chirp from the epoch origin, s (default back
    /// to back: `0, T`).
    pub chirp_starts_s: [f64; CHANNELS],
    /// Tags' uplink shifts `s_k`, Hz (received carrier `f_j + s_k/2`).
    pub tag_shifts_hz: [f64; TAGS],
    /// Tags' body positions, m (docs/marvel.md section 2).
    pub tag_positions: [Vec3; TAGS],
    /// The two opposing pairs (tag indices): (x pair, y pair).
    pub pairs: [(usize, usize); 2],
    /// Receive array (offsets from its centre, world axes, m).
    pub array: ArrayGeometry,
    /// Receive-chain phase offsets `theta_m(F)` to subtract, rad: empty, or
    /// `M x 8` row-major (antenna m, received channel `j * 4 + k`).
    pub calibration_rad: Vec<f64>,
    pub peak: PeakOptions,
    pub range: RangeConfig,
    pub range_coherence: RangeCoherence,
    pub range_window: RangeWindow,
    /// Weight the range profile by the peaks' magnitudes (the linear
    /// inverse transform of the channel) instead of unit weights.
    pub magnitude_weights: bool,
    pub music: MusicConfig,
    pub angle_combine: AngleCombine,
    pub heading: HeadingConfig,
    /// The Doppler-blind mu-locate baseline: no translational or rotational
    /// Doppler is removed (phases keep their ramp between the chirps, the
    /// timing range keeps the Doppler).
    pub ignore_doppler: bool,
    /// The decoding threshold of one peak, per-sample SNR, dB (the SX1276's
    /// SF12 demodulation limit, -20 dB: 16 dB after the 36 dB dechirp). A
    /// (channel, tag, antenna) in a multipath fade reads noise (about -27
    /// dB: the largest of 4096 bins): its frequency is anywhere in +-250 kHz
    /// and its phase is the reflections' sum, not the line of sight's. Such
    /// a peak is masked through the whole chain: a pair enters the
    /// chirp-timing range only when both its peaks clear it (one noise pair
    /// in the mean put the timing range kilometres off); a tag's channel
    /// enters MUSIC only when all its antennas clear it, and a tag without
    /// such a channel is left out of the combined angle; a phase group of
    /// the range profile keeps only its clear peaks. Where nothing clears it
    /// (the epoch's SNR test declines such an epoch anyway) every peak is
    /// used.
    pub min_peak_snr_db: f64,
}

impl EpochConfig {
    /// docs/marvel.md defaults: SF 12 / 500 kHz, channels 0 and 12
    /// (902.1 and 928.02 MHz), shifts 1-4 MHz, tags on a 0.66 m circle
    /// 0.30 m below the body origin, the 16 cm triangle, range 0-150 m.
    pub fn marvel() -> Self {
        let chirp = ChirpConfig::marvel();
        let t = chirp.duration_s();
        let (d, h) = (0.66, -0.30);
        let array = ArrayGeometry::triangle(0.16);
        let music = MusicConfig::for_array(&array);
        let channels_hz = [902.1e6, 902.1e6 + 2.16e6 * 12.0];
        let fringe = SPEED_OF_LIGHT / (2.0 * (channels_hz[1] - channels_hz[0]));
        Self {
            chirp,
            channels_hz,
            chirp_starts_s: [0.0, t],
            tag_shifts_hz: [1e6, 2e6, 3e6, 4e6],
            tag_positions: [[d / 2.0, 0.0, h], [-d / 2.0, 0.0, h], [0.0, d / 2.0, h], [0.0, -d / 2.0, h]],
            pairs: [(0, 1), (2, 3)],
            array,
            calibration_rad: Vec::new(),
            peak: PeakOptions::default(),
            range: RangeConfig { min_m: 0.0, max_m: 150.0, ..RangeConfig::default() },
            range_coherence: RangeCoherence::PerTag,
            range_window: RangeWindow::AroundTiming { half_width_m: fringe },
            magnitude_weights: true,
            music,
            angle_combine: AngleCombine::HarmonicMean,
            heading: HeadingConfig { min_omega_rad_s: 0.05, chirp_rate_hz_per_s: Some(chirp.chirp_rate_hz_per_s()) },
            ignore_doppler: false,
            min_peak_snr_db: -20.0,
        }
    }

    /// Received carrier of channel `j`, tag `k`: `f_j + s_k/2`, Hz.
    pub fn carrier_hz(&self, j: usize, k: usize) -> f64 {
        self.channels_hz[j] + self.tag_shifts_hz[k] / 2.0
    }

    /// Receive antennas `M`.
    pub fn antennas(&self) -> usize {
        self.array.len()
    }

    /// Samples of one epoch, `2 x 4 x M x N`.
    pub fn samples_per_epoch(&self) -> usize {
        CHANNELS * TAGS * self.antennas() * self.chirp.samples()
    }

    /// Centre time of channel j's chirp from the epoch origin, s.
    pub fn chirp_centre_s(&self, j: usize) -> f64 {
        self.chirp_starts_s[j] + self.chirp.duration_s() / 2.0
    }

    /// The reference time of the epoch's phases: the mean chirp centre, s.
    pub fn reference_time_s(&self) -> f64 {
        (0..CHANNELS).map(|j| self.chirp_centre_s(j)).sum::<f64>() / CHANNELS as f64
    }

    pub fn validate(&self) -> Result<()> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(finite(&self.channels_hz) && finite(&self.chirp_starts_s) && finite(&self.tag_shifts_hz)) {
            return Err(Error::NonFinite("epoch configuration".into()));
        }
        if self.channels_hz.iter().any(|&f| f <= 0.0) || self.channels_hz[0] == self.channels_hz[1] {
            return Err(Error::BadConfig("two distinct positive channel frequencies are needed".into()));
        }
        let mut seen = [false; TAGS];
        for &(a, b) in &self.pairs {
            for t in [a, b] {
                if t >= TAGS || seen[t] {
                    return Err(Error::BadConfig(format!("pairs {:?} must partition the 4 tags", self.pairs)));
                }
                seen[t] = true;
            }
        }
        let m = self.antennas();
        if m < 2 {
            return Err(Error::BadConfig("at least 2 receive antennas".into()));
        }
        if !(self.calibration_rad.is_empty() || self.calibration_rad.len() == m * CHANNELS * TAGS) {
            return Err(Error::Shape(format!("calibration: {} values for {m} x 8", self.calibration_rad.len())));
        }
        if let RangeWindow::AroundTiming { half_width_m } = self.range_window {
            if !(half_width_m > 0.0 && half_width_m.is_finite()) {
                return Err(Error::BadConfig(format!("range window half-width {half_width_m} m")));
            }
        }
        Ok(())
    }

    fn calibration(&self, m: usize, j: usize, k: usize) -> f64 {
        if self.calibration_rad.is_empty() {
            0.0
        } else {
            self.calibration_rad[m * CHANNELS * TAGS + j * TAGS + k]
        }
    }
}

/// What the tracker knows at this epoch (all optional but the clock error).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Corrections {
    /// The tags' clock error `eps` (`cfo_k = eps s_k`), from
    /// [`super::estimate_clock_error`] at rest; 0 if unknown.
    pub clock_error: f64,
    /// Fused body-origin velocity, m/s (world). `None`: 0 (at rest).
    pub velocity: Option<Vec3>,
    /// Direction from the controller to the drone (world, unit) for the
    /// Doppler prediction and the heading; `None`: this epoch's angle.
    pub direction: Option<Vec3>,
    /// Attitude `world_R_body` (its roll/pitch part feeds the heading, the
    /// whole of it the gear centre's lever-arm velocity).
    pub attitude: Option<Mat3>,
    /// Gyroscope body rate, rad/s.
    pub omega_body: Option<Vec3>,
    /// Absolute time of the epoch origin (s, recording time): removes the
    /// tags' whole clock phase `2 pi cfo_k t` (see [`PhaseCorrection`]).
    pub epoch_time_s: Option<f64>,
}

/// Everything one epoch yields. Per-chirp arrays use the index
/// `(j * 4 + k) * M + m`; per-pair arrays `(j * M + m) * 2 + p`.
#[derive(Debug, Clone, PartialEq)]
pub struct EpochFeatures {
    pub peaks: Vec<Peak>,
    /// Channel phases at `reference_time_s` (rad, wrapped).
    pub phases_rad: Vec<f64>,
    /// Received carriers `f_j + s_k/2`, index `j * 4 + k`, Hz.
    pub carriers_hz: Vec<f64>,
    /// Reference time from the epoch origin, s.
    pub reference_time_s: f64,
    /// Pair means (eq. 2), Hz.
    pub pair_mean_hz: Vec<f64>,
    /// Rotational shifts of the pairs' first tags (eq. 7 / 2, CFO
    /// difference removed), Hz.
    pub rotational_hz: Vec<f64>,
    /// The translational Doppler removed, per received carrier (index
    /// `j * 4 + k`), Hz.
    pub translational_hz: Vec<f64>,
    /// Chirp-timing term `-(BW/T) tau` from the pair means, Hz, and its
    /// standard deviation.
    pub timing_hz: f64,
    pub timing_sigma_hz: f64,
    /// The chirp-timing range `c0 tau / 2` of the tags' centroid, m, and its
    /// standard deviation.
    pub timing_range_m: f64,
    pub timing_range_sigma_m: f64,
    /// Phase range of the tags' centroid from the array centre (all
    /// antennas), m.
    pub range: RangeEstimate,
    /// Per-antenna phase ranges, m (NaN where an antenna's profile failed).
    pub antenna_ranges_m: Vec<f64>,
    /// MUSIC per tag (a tag without a clear channel: from all its channels,
    /// reported but not combined).
    pub tag_angles: Vec<MusicEstimate>,
    /// Which tags entered the combined angle (a channel whose peaks clear
    /// `min_peak_snr_db` on every antenna).
    pub tag_used: Vec<bool>,
    /// Consistency of the combined angle, rad per tangent axis: the spread
    /// of the two opposing pairs' mean directions,
    /// `sqrt(sum d_p^2 / (2 (n - 1)))` with `d_p` the angle between pair
    /// p's mean direction and the mean of the pairs'. The tags see the multipath through different
    /// fades (they are 0.47-0.66 m, 1.4-2 wavelengths, apart), so their
    /// disagreement measures the angle's multipath error, which the thermal
    /// bound does not. Pair means, because an opposing pair's lever arms
    /// from the centroid cancel whatever the attitude. `None` unless both
    /// pairs have both tags in use.
    pub angle_spread_rad: Option<f64>,
    /// Consistency of the phase range, m: the sample standard deviation of
    /// the phase groups' own ranges (each group's profile peak nearest the
    /// combined range, within one resolution) about their mean, per
    /// antenna and opposing pair (the pair's two per-tag groups averaged:
    /// their lever arms cancel) by default, after each antenna's expected
    /// offset (half its offset along the line of sight). Each group's
    /// phases see their own fades, so the scatter measures the multipath
    /// error; a common error (a wrong Doppler ramp, a wrong fringe) does
    /// not show in it. `None` with fewer than two.
    pub range_spread_m: Option<f64>,
    /// Combined angle, rad, and its direction.
    pub azimuth: f64,
    pub elevation: f64,
    pub direction: Vec3,
    pub heading: Option<HeadingEstimate>,
    /// Mean and minimum per-sample SNR of the 2 x 4 x M peaks, dB.
    pub snr_db: f64,
    pub min_snr_db: f64,
}

/// The epoch chain with its peak finder (FFT plan, downchirp, buffers)
/// allocated once.
pub struct EpochProcessor {
    config: EpochConfig,
    finder: PeakFinder,
}

impl EpochProcessor {
    pub fn new(config: EpochConfig) -> Result<Self> {
        config.validate()?;
        let finder = PeakFinder::new(config.chirp, config.peak.clone())?;
        Ok(Self { config, finder })
    }

    pub fn config(&self) -> &EpochConfig {
        &self.config
    }

    /// Runs the chain on one epoch's samples (layout in the module doc):
    /// the steps of the module doc, each a function below.
    ///
    /// Errors: [`Error::Shape`] for a wrong length, [`Error::NonFinite`] for
    /// bad samples or corrections, and the steps' own errors.
    pub fn process<S: Sample>(&mut self, samples: &[S], corrections: &Corrections) -> Result<EpochFeatures> {
        check_input(&self.config, samples.len(), corrections)?;
        // 1. Peaks, and which clear the decoding threshold.
        let peaks = self.find_peaks(samples)?;
        let c = &self.config;
        let clear = clear_peaks(&peaks, c.min_peak_snr_db);
        let grid = PeakGrid { peaks: &peaks, clear: &clear, antennas: c.antennas() };

        // 2. Angle per tag, combined; the line of sight the Doppler uses.
        let (tag_angles, tag_used) = tag_angles(c, &grid)?;
        let angles: Vec<(f64, f64)> =
            tag_angles.iter().zip(&tag_used).filter(|(_, &u)| u).map(|(e, _)| (e.azimuth, e.elevation)).collect();
        let (azimuth, elevation) = combine_angles(&angles, c.angle_combine)?;
        let direction = super::geometry::direction(azimuth, elevation);
        let u = line_of_sight(corrections, direction)?;

        // 3. CFO, translational and rotational Doppler; the chirp-timing range.
        let cfo: Vec<f64> = c.tag_shifts_hz.iter().map(|&s| cfo_hz(corrections.clock_error, s)).collect();
        let v_gear = gear_velocity(c, corrections)?;
        let carriers = carriers_hz(c);
        let translational: Vec<f64> = carriers
            .iter()
            .map(|&f| if c.ignore_doppler { 0.0 } else { translational_doppler_hz(f, &u, &v_gear) })
            .collect();
        let pairs = pair_shifts(c, &grid, &cfo, &translational);
        let timing = chirp_timing(c, &pairs.timing_terms);
        let doppler = ramp_doppler(c, &grid, &translational, &pairs.rotational_hz);

        // 4. Channel phases at the reference time.
        let t_ref = c.reference_time_s();
        let phases_rad = channel_phases(c, &grid, &cfo, &doppler, corrections.epoch_time_s);

        // 5. Phase range and the consistency spreads.
        let phase = phase_range(c, &grid, &phases_rad, timing.range_m)?;
        let angle_spread_rad = angle_spread(c, &tag_angles, &tag_used, direction);
        let range_spread_m = range_spread(c, &phase, direction);

        // 6. Heading.
        let heading = heading(c, &grid, &cfo, corrections, u, v_gear, phase.range.range_m);

        let (snr_db, min_snr_db) = snr_summary(&peaks);
        Ok(EpochFeatures {
            peaks,
            phases_rad,
            carriers_hz: carriers,
            reference_time_s: t_ref,
            pair_mean_hz: pairs.pair_mean_hz,
            rotational_hz: pairs.rotational_hz,
            translational_hz: translational,
            timing_hz: timing.hz,
            timing_sigma_hz: timing.sigma_hz,
            timing_range_m: timing.range_m,
            timing_range_sigma_m: timing.range_sigma_m,
            range: phase.range,
            antenna_ranges_m: phase.antenna_ranges_m,
            tag_angles,
            tag_used: tag_used.to_vec(),
            angle_spread_rad,
            range_spread_m,
            azimuth,
            elevation,
            direction,
            heading,
            snr_db,
            min_snr_db,
        })
    }

    /// Step 1: one peak per chirp, in the sample layout's order.
    fn find_peaks<S: Sample>(&mut self, samples: &[S]) -> Result<Vec<Peak>> {
        let n = self.config.chirp.samples();
        let mut peaks = Vec::with_capacity(CHANNELS * TAGS * self.config.antennas());
        for chirp in samples.chunks_exact(n) {
            peaks.push(self.finder.process(chirp)?);
        }
        Ok(peaks)
    }
}

/// The epoch's peaks in their layout (index `(j * 4 + k) * M + m`) and which
/// of them clear the decoding threshold ([`clear_peaks`]).
struct PeakGrid<'a> {
    peaks: &'a [Peak],
    clear: &'a [bool],
    antennas: usize,
}

impl PeakGrid<'_> {
    fn index(&self, j: usize, k: usize, m: usize) -> usize {
        (j * TAGS + k) * self.antennas + m
    }

    fn peak(&self, j: usize, k: usize, m: usize) -> &Peak {
        &self.peaks[self.index(j, k, m)]
    }

    fn clear(&self, j: usize, k: usize, m: usize) -> bool {
        self.clear[self.index(j, k, m)]
    }

    /// Both peaks of the pair `(a, b)` on channel `j`, antenna `m` clear.
    fn pair_clear(&self, j: usize, (a, b): (usize, usize), m: usize) -> bool {
        self.clear(j, a, m) && self.clear(j, b, m)
    }
}

/// The chain's input checks: the epoch's length and a finite clock error.
fn check_input(c: &EpochConfig, samples: usize, corrections: &Corrections) -> Result<()> {
    if samples != c.samples_per_epoch() {
        return Err(Error::Shape(format!(
            "an epoch is 2 x 4 x {} x {} = {} samples, got {samples}",
            c.antennas(),
            c.chirp.samples(),
            c.samples_per_epoch(),
        )));
    }
    if !corrections.clock_error.is_finite() {
        return Err(Error::NonFinite("clock error".into()));
    }
    Ok(())
}

/// Which peaks clear the decoding threshold `min_peak_snr_db` (per-sample
/// SNR, dB); if none does, all of them (the epoch's SNR test declines such
/// an epoch anyway).
fn clear_peaks(peaks: &[Peak], min_peak_snr_db: f64) -> Vec<bool> {
    let min_snr = 10f64.powf(min_peak_snr_db / 10.0);
    let mut clear: Vec<bool> = peaks.iter().map(|p| p.snr >= min_snr).collect();
    if !clear.iter().any(|&b| b) {
        clear.iter_mut().for_each(|b| *b = true);
    }
    clear
}

/// Received carriers `f_j + s_k/2`, index `j * 4 + k`, Hz.
fn carriers_hz(c: &EpochConfig) -> Vec<f64> {
    (0..CHANNELS).flat_map(|j| (0..TAGS).map(move |k| (j, k))).map(|(j, k)| c.carrier_hz(j, k)).collect()
}

/// Step 2: MUSIC per tag on the calibrated centre phases of its channels
/// whose peaks clear the threshold on every antenna (a snapshot needs all
/// antennas), and which tags enter the combined angle. A tag without a
/// clear channel still gets its (reported, unused) angle from all channels;
/// no tag in use: all are.
fn tag_angles(c: &EpochConfig, grid: &PeakGrid) -> Result<(Vec<MusicEstimate>, [bool; TAGS])> {
    let m_ant = grid.antennas;
    let centre_phase = |j: usize, k: usize, m: usize| grid.peak(j, k, m).amplitude_centre.arg() - c.calibration(m, j, k);
    let mut tag_angles = Vec::with_capacity(TAGS);
    let mut tag_used = [false; TAGS];
    for (k, used) in tag_used.iter_mut().enumerate() {
        let clear_channels: Vec<usize> = (0..CHANNELS).filter(|&j| (0..m_ant).all(|m| grid.clear(j, k, m))).collect();
        *used = !clear_channels.is_empty();
        let channels: Vec<usize> = if *used { clear_channels } else { (0..CHANNELS).collect() };
        let phases: Vec<f64> = (0..m_ant)
            .flat_map(|m| channels.iter().map(move |&j| (j, m)))
            .map(|(j, m)| centre_phase(j, k, m))
            .collect();
        let freqs: Vec<f64> = channels.iter().map(|&j| c.carrier_hz(j, k)).collect();
        tag_angles.push(music(&c.array, &c.music, &phases, &freqs)?);
    }
    if !tag_used.iter().any(|&u| u) {
        tag_used = [true; TAGS];
    }
    Ok((tag_angles, tag_used))
}

/// The direction the Doppler prediction and the heading use: the tracker's
/// (normalised) when given, else this epoch's angle.
fn line_of_sight(corrections: &Corrections, direction: Vec3) -> Result<Vec3> {
    match corrections.direction {
        Some(d) => normalize(&d).ok_or_else(|| Error::NonFinite("direction".into())),
        None => Ok(direction),
    }
}

/// Velocity of the tags' centroid, m/s (world): the body velocity plus the
/// lever arm `R (omega x r_c)` when the attitude and rate are known; 0
/// without a velocity.
fn gear_velocity(c: &EpochConfig, corrections: &Corrections) -> Result<Vec3> {
    let centroid = c.tag_positions.iter().fold([0.0; 3], |s, r| add(&s, &r.map(|x| x / TAGS as f64)));
    let v_gear = match (corrections.velocity, corrections.attitude, corrections.omega_body) {
        (Some(v), Some(r), Some(w)) => add(&v, &mat_vec(&r, &cross(&w, &centroid))),
        (Some(v), _, _) => v,
        (None, _, _) => [0.0; 3],
    };
    if v_gear.iter().any(|x| !x.is_finite()) {
        return Err(Error::NonFinite("velocity".into()));
    }
    Ok(v_gear)
}

/// Per pair (index `(j * M + m) * 2 + p`): the pair mean (eq. 2), the
/// rotational shift of its first tag (eq. 7 / 2, CFO difference removed),
/// and its chirp-timing term `(value Hz, variance Hz^2, both peaks clear)`.
struct PairShifts {
    pair_mean_hz: Vec<f64>,
    rotational_hz: Vec<f64>,
    timing_terms: Vec<(f64, f64, bool)>,
}

fn pair_shifts(c: &EpochConfig, grid: &PeakGrid, cfo: &[f64], translational: &[f64]) -> PairShifts {
    let m_ant = grid.antennas;
    let mut pair_mean_hz = vec![0.0; CHANNELS * m_ant * 2];
    let mut rotational_hz = vec![0.0; CHANNELS * m_ant * 2];
    let mut timing_terms: Vec<(f64, f64, bool)> = Vec::with_capacity(CHANNELS * m_ant * 2);
    for j in 0..CHANNELS {
        for m in 0..m_ant {
            for (p, &(a, b)) in c.pairs.iter().enumerate() {
                let (pa, pb) = (grid.peak(j, a, m), grid.peak(j, b, m));
                let i = (j * m_ant + m) * 2 + p;
                pair_mean_hz[i] = pair_mean(pa.frequency_hz, pb.frequency_hz);
                rotational_hz[i] = pair_half_difference(pa.frequency_hz, pb.frequency_hz) - 0.5 * (cfo[a] - cfo[b]);
                let t = pair_mean_hz[i]
                    - 0.5 * (cfo[a] + cfo[b])
                    - 0.5 * (translational[j * TAGS + a] + translational[j * TAGS + b]);
                let variance = 0.25 * (pa.frequency_sigma_hz.powi(2) + pb.frequency_sigma_hz.powi(2));
                timing_terms.push((t, variance, grid.pair_clear(j, (a, b), m)));
            }
        }
    }
    PairShifts { pair_mean_hz, rotational_hz, timing_terms }
}

/// The chirp-timing term `-(BW/T) tau` (Hz) and the range `c0 tau / 2` of
/// the tags' centroid (m), each with its 1-sigma.
struct Timing {
    hz: f64,
    sigma_hz: f64,
    range_m: f64,
    range_sigma_m: f64,
}

fn chirp_timing(c: &EpochConfig, terms: &[(f64, f64, bool)]) -> Timing {
    let (hz, sigma_hz) = timing_mean(terms);
    let tau = delay_from_frequency_s(&c.chirp, hz);
    Timing {
        hz,
        sigma_hz,
        range_m: SPEED_OF_LIGHT * tau / 2.0,
        range_sigma_m: SPEED_OF_LIGHT / 2.0 * sigma_hz / c.chirp.chirp_rate_hz_per_s(),
    }
}

/// Per-tag Doppler for the phase ramp (index `j * 4 + k`, Hz): translation +
/// the tag's rotational shift (sign + for a pair's first tag), averaged
/// over the antennas where both of the pair's peaks are clear: one noise
/// peak's half difference is up to 125 kHz, and its ramp scrambles the
/// pair's phases on every antenna. No clear antenna: no rotational shift is
/// removed. All 0 for the Doppler-blind baseline.
fn ramp_doppler(c: &EpochConfig, grid: &PeakGrid, translational: &[f64], rotational_hz: &[f64]) -> [f64; CHANNELS * TAGS] {
    let m_ant = grid.antennas;
    let mut doppler = [0.0; CHANNELS * TAGS];
    if c.ignore_doppler {
        return doppler;
    }
    for j in 0..CHANNELS {
        for (p, &(a, b)) in c.pairs.iter().enumerate() {
            let clear_antennas: Vec<usize> = (0..m_ant).filter(|&m| grid.pair_clear(j, (a, b), m)).collect();
            let rot = if clear_antennas.is_empty() {
                0.0
            } else {
                clear_antennas.iter().map(|&m| rotational_hz[(j * m_ant + m) * 2 + p]).sum::<f64>()
                    / clear_antennas.len() as f64
            };
            doppler[j * TAGS + a] = translational[j * TAGS + a] + rot;
            doppler[j * TAGS + b] = translational[j * TAGS + b] - rot;
        }
    }
    doppler
}

/// Step 4: every chirp's channel phase at the epoch's reference time (eq. 3),
/// its CFO and Doppler ramps and calibration removed (rad, wrapped).
fn channel_phases(c: &EpochConfig, grid: &PeakGrid, cfo: &[f64], doppler: &[f64], epoch_time_s: Option<f64>) -> Vec<f64> {
    let t_ref = c.reference_time_s();
    let mut phases_rad = vec![0.0; grid.peaks.len()];
    for j in 0..CHANNELS {
        for k in 0..TAGS {
            let correction = PhaseCorrection { cfo_hz: cfo[k], doppler_hz: doppler[j * TAGS + k], epoch_time_s };
            for m in 0..grid.antennas {
                let raw = grid.peak(j, k, m).amplitude_centre.arg();
                phases_rad[grid.index(j, k, m)] =
                    channel_phase(raw, c.chirp_centre_s(j), t_ref, c.calibration(m, j, k), &correction);
            }
        }
    }
    phases_rad
}

/// One antenna's phase groups, each with its tag when it has one (groups
/// per tag); `mask` says which peaks may enter. A group needs two peaks
/// (one frequency carries no range).
type AntennaGroups = Vec<(PhaseGroup, Option<usize>)>;

fn phase_groups(c: &EpochConfig, grid: &PeakGrid, phases_rad: &[f64], m: usize, mask: &[bool]) -> Result<AntennaGroups> {
    let weight = |p: &Peak| if c.magnitude_weights { p.amplitude_centre.norm() } else { 1.0 };
    let allowed = |j: usize, k: usize| mask[grid.index(j, k, m)];
    let phase = |j: usize, k: usize| phases_rad[grid.index(j, k, m)];
    let mut groups = Vec::new();
    let mut push = |sel: Vec<(usize, usize)>, tag: Option<usize>| -> Result<()> {
        if sel.len() >= 2 {
            groups.push((
                PhaseGroup::new(
                    sel.iter().map(|&(j, k)| c.carrier_hz(j, k)).collect(),
                    sel.iter().map(|&(j, k)| phase(j, k)).collect(),
                    sel.iter().map(|&(j, k)| weight(grid.peak(j, k, m))).collect(),
                    sel.iter().map(|&(j, k)| grid.peak(j, k, m).phase_sigma_rad).collect(),
                )?,
                tag,
            ));
        }
        Ok(())
    };
    match c.range_coherence {
        RangeCoherence::AcrossTags => {
            push(
                (0..CHANNELS).flat_map(|j| (0..TAGS).map(move |k| (j, k))).filter(|&(j, k)| allowed(j, k)).collect(),
                None,
            )?;
        }
        RangeCoherence::PerTag => {
            for k in 0..TAGS {
                push((0..CHANNELS).map(|j| (j, k)).filter(|&(j, k)| allowed(j, k)).collect(), Some(k))?;
            }
        }
        RangeCoherence::PairSums => {
            let sel: Vec<(usize, (usize, usize))> = (0..CHANNELS)
                .flat_map(|j| c.pairs.iter().map(move |&p| (j, p)))
                .filter(|&(j, (a, b))| allowed(j, a) && allowed(j, b))
                .collect();
            if sel.len() >= 2 {
                groups.push((
                    PhaseGroup::new(
                        sel.iter().map(|&(j, (a, b))| c.carrier_hz(j, a) + c.carrier_hz(j, b)).collect(),
                        sel.iter().map(|&(j, (a, b))| super::wrap_angle(phase(j, a) + phase(j, b))).collect(),
                        sel.iter().map(|&(j, (a, b))| weight(grid.peak(j, a, m)) * weight(grid.peak(j, b, m))).collect(),
                        sel.iter()
                            .map(|&(j, (a, b))| grid.peak(j, a, m).phase_sigma_rad.hypot(grid.peak(j, b, m).phase_sigma_rad))
                            .collect(),
                    )?,
                    None,
                ));
            }
        }
    }
    Ok(groups)
}

/// Where the phase range is searched: the configured interval, or around the
/// chirp-timing range `timing_range_m` (m) with the fringe nearest to it
/// ([`RangeWindow::AroundTiming`]).
fn range_search(c: &EpochConfig, timing_range_m: f64) -> RangeConfig {
    let mut range_config = c.range.clone();
    if let RangeWindow::AroundTiming { half_width_m } = c.range_window {
        let centre = timing_range_m.clamp(c.range.min_m, c.range.max_m);
        range_config.min_m = (centre - half_width_m).max(c.range.min_m);
        range_config.max_m = (centre + half_width_m).min(c.range.max_m);
        if range_config.max_m <= range_config.min_m {
            range_config.max_m = range_config.min_m + 2.0 * half_width_m;
        }
        range_config.select = RangeSelect::NearestTo(timing_range_m);
    }
    range_config
}

/// Step 5: the phase range of all antennas' groups, each antenna's own, and
/// the groups with their (antenna, tag) for the range's spread.
struct PhaseRange {
    range: RangeEstimate,
    antenna_ranges_m: Vec<f64>,
    groups: Vec<PhaseGroup>,
    group_of: Vec<(usize, Option<usize>)>,
}

fn phase_range(c: &EpochConfig, grid: &PeakGrid, phases_rad: &[f64], timing_range_m: f64) -> Result<PhaseRange> {
    let m_ant = grid.antennas;
    // The clear peaks' groups; where no group is left, every peak's.
    let mut per_antenna: Vec<AntennaGroups> =
        (0..m_ant).map(|m| phase_groups(c, grid, phases_rad, m, grid.clear)).collect::<Result<_>>()?;
    if per_antenna.iter().all(|g| g.is_empty()) {
        let all = vec![true; grid.peaks.len()];
        per_antenna = (0..m_ant).map(|m| phase_groups(c, grid, phases_rad, m, &all)).collect::<Result<_>>()?;
    }
    let range_config = range_search(c, timing_range_m);
    let mut groups = Vec::new();
    let mut group_of = Vec::new();
    let mut antenna_ranges_m = Vec::with_capacity(m_ant);
    for (m, antenna) in per_antenna.into_iter().enumerate() {
        let (antenna, tags): (Vec<PhaseGroup>, Vec<Option<usize>>) = antenna.into_iter().unzip();
        antenna_ranges_m.push(estimate_range(&antenna, &range_config).map_or(f64::NAN, |e| e.range_m));
        groups.extend(antenna);
        group_of.extend(tags.into_iter().map(|k| (m, k)));
    }
    let range = estimate_range(&groups, &range_config)?;
    Ok(PhaseRange { range, antenna_ranges_m, groups, group_of })
}

/// The combined angle's consistency (see [`EpochFeatures::angle_spread_rad`]).
///
/// A tag's direction differs from the centroid's by its lever arm
/// `R (t_k - c)` (0.33 m: 3 degrees of direction at 6 m), which depends on
/// the yaw — unobservable on a straight flight, and a yaw error left in the
/// lever arm reads as scatter. An opposing pair's lever arms are opposite,
/// so the pair's mean direction is the centroid's to first order whatever
/// the attitude: the spread is taken over pair means.
fn angle_spread(c: &EpochConfig, tag_angles: &[MusicEstimate], tag_used: &[bool; TAGS], direction: Vec3) -> Option<f64> {
    let pair_directions: Vec<Vec3> = c
        .pairs
        .iter()
        .filter(|&&(a, b)| tag_used[a] && tag_used[b])
        .filter_map(|&(a, b)| normalize(&add(&tag_angles[a].direction, &tag_angles[b].direction)))
        .collect();
    let pair_mean = normalize(&pair_directions.iter().fold([0.0; 3], |s, d| add(&s, d))).unwrap_or(direction);
    direction_spread(&pair_directions, &pair_mean)
}

/// The phase range's consistency (see [`EpochFeatures::range_spread_m`]):
/// per antenna and opposing pair (the pair's two per-tag groups averaged:
/// their lever arms cancel, as for the angle), or per group without tags,
/// after the antenna's expected offset: half its offset along the line of
/// sight (the receive leg alone changes).
fn range_spread(c: &EpochConfig, phase: &PhaseRange, direction: Vec3) -> Option<f64> {
    let group_deviation = group_deviations_m(&phase.groups, phase.range.range_m);
    let antenna_offset = |m: usize| -0.5 * dot(&c.array.elements()[m], &direction);
    let of_tag = |m: usize, k: usize| {
        phase.group_of.iter().zip(&group_deviation).find(|(&(gm, gk), _)| gm == m && gk == Some(k)).and_then(|(_, &d)| d)
    };
    let mut deviations: Vec<f64> = phase
        .group_of
        .iter()
        .zip(&group_deviation)
        .filter(|(&(_, k), _)| k.is_none())
        .filter_map(|(&(m, _), &d)| Some(d? - antenna_offset(m)))
        .collect();
    for m in 0..c.antennas() {
        for &(a, b) in &c.pairs {
            if let (Some(da), Some(db)) = (of_tag(m, a), of_tag(m, b)) {
                deviations.push(0.5 * (da + db) - antenna_offset(m));
            }
        }
    }
    rms_spread(&deviations)
}

/// Step 6: the yaw from the pairs' frequency differences (eqs. 7-8) when the
/// attitude and the gyroscope's rate are given; only pairs whose peaks are
/// both clear (a noise peak's frequency is no rotational shift).
fn heading(
    c: &EpochConfig,
    grid: &PeakGrid,
    cfo: &[f64],
    corrections: &Corrections,
    u: Vec3,
    v_gear: Vec3,
    range_m: f64,
) -> Option<HeadingEstimate> {
    let (Some(r), Some(w)) = (corrections.attitude, corrections.omega_body) else {
        return None;
    };
    let (_, roll_pitch) = split_yaw(&r);
    let mut observations = Vec::with_capacity(CHANNELS * grid.antennas * 2);
    for j in 0..CHANNELS {
        for m in 0..grid.antennas {
            for &(a, b) in &c.pairs {
                if !grid.pair_clear(j, (a, b), m) {
                    continue;
                }
                let (pa, pb) = (grid.peak(j, a, m), grid.peak(j, b, m));
                observations.push(PairObservation {
                    tag_a: c.tag_positions[a],
                    tag_b: c.tag_positions[b],
                    carrier_hz: 0.5 * (c.carrier_hz(j, a) + c.carrier_hz(j, b)),
                    difference_hz: pa.frequency_hz - pb.frequency_hz - (cfo[a] - cfo[b]),
                    sigma_hz: pa.frequency_sigma_hz.hypot(pb.frequency_sigma_hz),
                });
            }
        }
    }
    let geometry = YawGeometry {
        roll_pitch,
        omega_body: w,
        direction: u,
        velocity: corrections.velocity.map(|_| v_gear),
        range_m: Some(range_m),
    };
    solve_yaw(&observations, &geometry, &c.heading)
}

/// Mean and minimum per-sample SNR of the peaks, dB.
fn snr_summary(peaks: &[Peak]) -> (f64, f64) {
    let snrs: Vec<f64> = peaks.iter().map(|p| 10.0 * p.snr.max(1e-30).log10()).collect();
    let snr_db = snrs.iter().sum::<f64>() / snrs.len() as f64;
    let min_snr_db = snrs.iter().copied().fold(f64::INFINITY, f64::min);
    (snr_db, min_snr_db)
}

/// Per-axis RMS deviation (rad) of unit directions from their combined
/// direction `mean` (see [`EpochFeatures::angle_spread_rad`]); `None` for
/// fewer than two.
fn direction_spread(directions: &[Vec3], mean: &Vec3) -> Option<f64> {
    let n = directions.len();
    (n >= 2).then(|| {
        let sum: f64 = directions.iter().map(|d| super::geometry::dot(d, mean).clamp(-1.0, 1.0).acos().powi(2)).sum();
        (sum / (2.0 * (n - 1) as f64)).sqrt()
    })
}

/// Sample standard deviation (over `n - 1`, same unit as the values);
/// `None` for fewer than two.
fn rms_spread(deviations: &[f64]) -> Option<f64> {
    let n = deviations.len();
    (n >= 2).then(|| {
        let mean = deviations.iter().sum::<f64>() / n as f64;
        (deviations.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    })
}

/// The chirp-timing term (Hz) and its 1-sigma from the pairs' terms
/// `(value Hz, variance Hz^2, clear)`: the plain mean over the clear pairs
/// (both peaks detected), or over all when none is clear (the epoch's SNR
/// test declines such an epoch anyway). Plain, not inverse-variance: the
/// weighted mean's smaller sigma settled wrong fringes sooner behind a
/// ground reflection (measured: 20 m with the ground, 2 of 3 seeds a fringe
/// or more off).
fn timing_mean(terms: &[(f64, f64, bool)]) -> (f64, f64) {
    let clear: Vec<&(f64, f64, bool)> = terms.iter().filter(|t| t.2).collect();
    let used: Vec<&(f64, f64, bool)> = if clear.is_empty() { terms.iter().collect() } else { clear };
    let count = used.len() as f64;
    let sum: f64 = used.iter().map(|t| t.0).sum();
    let variance: f64 = used.iter().map(|t| t.1).sum();
    (sum / count, variance.sqrt() / count)
}

#[cfg(test)]
pub(crate) mod sim {
    //! An exact simulator of one epoch per docs/marvel.md section 6 (time of
    //! flight, translation and rotation along the chirp, tag clock, noise),
    //! for the tests.

    use num_complex::{Complex32, Complex64};
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    use super::super::geometry::{add, cross, mat_mul, mat_vec, norm, sub, Mat3, Vec3, IDENTITY};
    use super::{EpochConfig, CHANNELS, TAGS};
    use crate::SPEED_OF_LIGHT;

    #[derive(Debug, Clone)]
    pub struct Scene {
        /// Array centre (= tx antenna), m.
        pub rho: Vec3,
        /// Body origin at the epoch origin, m, and its velocity, m/s.
        pub position: Vec3,
        pub velocity: Vec3,
        /// Attitude at the epoch origin and the body rate, rad/s.
        pub attitude: Mat3,
        pub omega_body: Vec3,
        pub clock_error: f64,
        pub phi_tag: f64,
        /// Absolute time of the epoch origin, s.
        pub epoch_time_s: f64,
        /// Per-sample SNR, dB (infinite: no noise).
        pub snr_db: f64,
        /// A second path: extra length (m) and complex coefficient.
        pub reflector: Option<(f64, Complex64)>,
    }

    impl Scene {
        pub fn hover(position: Vec3, snr_db: f64) -> Self {
            Self {
                rho: [0.0, 0.0, 0.0],
                position,
                velocity: [0.0; 3],
                attitude: IDENTITY,
                omega_body: [0.0; 3],
                clock_error: 0.0,
                phi_tag: 0.3,
                epoch_time_s: 0.0,
                snr_db,
                reflector: None,
            }
        }

        /// `R(t) = R0 exp([omega_B] t)` (Rodrigues).
        pub fn attitude_at(&self, t: f64) -> Mat3 {
            let w = self.omega_body.map(|x| x * t);
            let angle = norm(&w);
            if angle < 1e-15 {
                return self.attitude;
            }
            let k = w.map(|x| x / angle);
            let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
            let kx2 = mat_mul(&kx, &kx);
            let (s, c) = angle.sin_cos();
            let mut e = IDENTITY;
            for i in 0..3 {
                for j in 0..3 {
                    e[i][j] += s * kx[i][j] + (1.0 - c) * kx2[i][j];
                }
            }
            mat_mul(&self.attitude, &e)
        }

        /// Tag k's world position at `t` (s from the epoch origin).
        pub fn tag_at(&self, config: &EpochConfig, k: usize, t: f64) -> Vec3 {
            add(
                &add(&self.position, &self.velocity.map(|x| x * t)),
                &mat_vec(&self.attitude_at(t), &config.tag_positions[k]),
            )
        }

        /// The tags' centroid at `t`.
        pub fn centroid_at(&self, config: &EpochConfig, t: f64) -> Vec3 {
            (0..TAGS).fold([0.0; 3], |s, k| add(&s, &self.tag_at(config, k, t).map(|x| x / TAGS as f64)))
        }

        /// World body rate `R omega_B` is not needed: omega is body-fixed.
        pub fn _unused(&self) -> Vec3 {
            cross(&self.omega_body, &[0.0; 3])
        }
    }

    pub fn simulate(config: &EpochConfig, scene: &Scene, rng: &mut StdRng) -> Vec<Complex32> {
        let n = config.chirp.samples();
        let fs = config.chirp.sample_rate_hz();
        let m_ant = config.antennas();
        let noise_power = 10f64.powf(-scene.snr_db / 10.0);
        let normal = Normal::new(0.0, (noise_power / 2.0).sqrt().max(1e-300)).unwrap();
        let mut out = Vec::with_capacity(config.samples_per_epoch());
        for j in 0..CHANNELS {
            for k in 0..TAGS {
                let carrier = config.carrier_hz(j, k);
                let cfo = scene.clock_error * config.tag_shifts_hz[k];
                for m in 0..m_ant {
                    let rx = add(&scene.rho, &config.array.elements()[m]);
                    for i in 0..n {
                        let t_chirp = i as f64 / fs;
                        let t = config.chirp_starts_s[j] + t_chirp;
                        let p = scene.tag_at(config, k, t);
                        let path = norm(&sub(&p, &scene.rho)) + norm(&sub(&p, &rx));
                        let mut y = Complex64::new(0.0, 0.0);
                        let paths = [(0.0, Complex64::new(1.0, 0.0))];
                        let extra: Vec<(f64, Complex64)> = scene.reflector.into_iter().collect();
                        for &(dl, g) in paths.iter().chain(extra.iter()) {
                            let tau = (path + dl) / SPEED_OF_LIGHT;
                            let carrier_cycles = (carrier * tau).rem_euclid(1.0);
                            let clock_cycles = (cfo * (scene.epoch_time_s + t)).rem_euclid(1.0);
                            let chirp_cycles = config.chirp.phase_cycles(t_chirp - tau);
                            let psi =
                                std::f64::consts::TAU * (-carrier_cycles + clock_cycles + chirp_cycles) + scene.phi_tag;
                            y += g * Complex64::from_polar(1.0, psi);
                        }
                        if scene.snr_db.is_finite() {
                            y += Complex64::new(normal.sample(rng), normal.sample(rng));
                        }
                        out.push(Complex32::new(y.re as f32, y.im as f32));
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::doppler::estimate_clock_error;
    use super::super::geometry::{
        azimuth_elevation, dot, mat_mul, norm, roll_pitch_matrix, rotation_z, sub, transpose,
    };
    use super::sim::{simulate, Scene};
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    fn truth(config: &EpochConfig, scene: &Scene) -> (f64, f64, f64) {
        let c = scene.centroid_at(config, config.reference_time_s());
        let d = sub(&c, &scene.rho);
        let (az, el) = azimuth_elevation(&d);
        (norm(&d), az, el)
    }

    fn angle_error(f: &EpochFeatures, az: f64, el: f64) -> f64 {
        dot(&f.direction, &super::super::geometry::direction(az, el)).clamp(-1.0, 1.0).acos()
    }

    #[test]
    fn timing_mean_leaves_out_faded_pairs() {
        // Two clear pairs and one pair with a noise peak 200 kHz away: the
        // mean is the clear pairs' own.
        let terms = [(10.0, 4.0, true), (13.0, 1.0, true), (2.0e5, 1.0, false)];
        let (mean, sigma) = timing_mean(&terms);
        assert!((mean - 11.5).abs() < 1e-12, "{mean}");
        assert!((sigma - 5f64.sqrt() / 2.0).abs() < 1e-12);
        // None clear: the plain mean of all (as before the test existed).
        let (mean, sigma) = timing_mean(&[(1.0, 1.0, false), (3.0, 1.0, false)]);
        assert!((mean - 2.0).abs() < 1e-12 && (sigma - 2f64.sqrt() / 2.0).abs() < 1e-12);
    }

    fn peak_with_snr(snr: f64) -> Peak {
        let zero = num_complex::Complex64::new(0.0, 0.0);
        Peak {
            frequency_hz: 0.0,
            amplitude: zero,
            amplitude_centre: zero,
            snr,
            noise_power: 1.0,
            frequency_sigma_hz: 1.0,
            phase_sigma_rad: 0.1,
            bin: 0,
            iterations: 0,
        }
    }

    #[test]
    fn clear_peaks_masks_the_faded_and_keeps_all_when_none_clears() {
        // -20 dB threshold: 0.01 in linear per-sample SNR.
        let peaks = [peak_with_snr(0.5), peak_with_snr(0.005), peak_with_snr(0.01)];
        assert_eq!(clear_peaks(&peaks, -20.0), vec![true, false, true]);
        // None clears 30 dB: every peak is used.
        assert_eq!(clear_peaks(&peaks, 30.0), vec![true; 3]);
    }

    #[test]
    fn range_search_is_around_the_timing_range_within_the_interval() {
        let c = EpochConfig::marvel();
        let RangeWindow::AroundTiming { half_width_m } = c.range_window else { panic!("default window") };
        let around = range_search(&c, 20.0);
        assert!((around.min_m - (20.0 - half_width_m)).abs() < 1e-12);
        assert!((around.max_m - (20.0 + half_width_m)).abs() < 1e-12);
        assert_eq!(around.select, RangeSelect::NearestTo(20.0));
        // A timing range beyond the interval: the window keeps its width inside it.
        let beyond = range_search(&c, -3.0);
        assert_eq!(beyond.min_m, c.range.min_m);
        assert!((beyond.max_m - (c.range.min_m + half_width_m)).abs() < 1e-12);
        let full = range_search(&EpochConfig { range_window: RangeWindow::Full, ..c.clone() }, 20.0);
        assert_eq!((full.min_m, full.max_m), (c.range.min_m, c.range.max_m));
    }

    #[test]
    fn spreads_of_directions_and_deviations() {
        let mean = [0.0, 1.0, 0.0];
        let tilt = |a: f64| [a.sin(), a.cos(), 0.0];
        // Two tags 0.1 rad either side: sum of squares 0.02 over 2 (n - 1) = 2.
        let s = direction_spread(&[tilt(0.1), tilt(-0.1)], &mean).unwrap();
        assert!((s - 0.1).abs() < 1e-9, "{s}");
        assert!(direction_spread(&[tilt(0.1)], &mean).is_none());
        assert!((rms_spread(&[0.3, -0.3, 0.0]).unwrap() - 0.3).abs() < 1e-12);
        assert!((rms_spread(&[1.3, 0.7, 1.0]).unwrap() - 0.3).abs() < 1e-12);
        assert!(rms_spread(&[1.0]).is_none());
    }

    /// One (channel, tag, antenna) in a deep fade: its chirp is noise only
    /// (as the floor's image leaves it in a reflecting room). Masked, the
    /// angle and the range stay exact and their spreads small; without the
    /// mask (threshold -inf, the chain before the mask) the faded tag's
    /// random phase pulls the angle and widens both spreads.
    #[test]
    fn a_faded_peak_is_masked_out_of_the_angle_and_the_range() {
        let config = EpochConfig::marvel();
        let mut rng = StdRng::seed_from_u64(31);
        let mut scene = Scene::hover([-3.0, 12.0, 2.0], 10.0);
        scene.clock_error = 0.5e-6;
        let mut y = simulate(&config, &scene, &mut rng);
        // Chirp (j = 0, k = 1, m = 2) replaced by the noise alone.
        let (n, m_ant) = (config.chirp.samples(), config.antennas());
        let faded_index = m_ant + 2; // (j 0, tag 1, antenna 2): (j * 4 + k) * M + m
        let start = faded_index * n;
        let sigma = (10f64.powf(-scene.snr_db / 10.0) / 2.0).sqrt();
        let normal = rand_distr::Normal::new(0.0, sigma).unwrap();
        for v in &mut y[start..start + n] {
            use rand_distr::Distribution;
            *v = num_complex::Complex32::new(normal.sample(&mut rng) as f32, normal.sample(&mut rng) as f32);
        }
        let corrections =
            Corrections { clock_error: scene.clock_error, attitude: Some(scene.attitude), ..Default::default() };
        let (r, az, el) = truth(&config, &scene);
        let masked = EpochProcessor::new(config.clone()).unwrap().process(&y, &corrections).unwrap();
        let unmasked = EpochProcessor::new(EpochConfig { min_peak_snr_db: f64::NEG_INFINITY, ..config.clone() })
            .unwrap()
            .process(&y, &corrections)
            .unwrap();
        let faded = &masked.peaks[faded_index];
        println!(
            "faded peak {:.1} dB; angle error masked {:.3} deg (spread {:.3} deg, tags {:?}), unmasked {:.3} deg \
             (spread {:.3} deg); range error masked {:+.4} m (spread {:.4} m), unmasked {:+.4} m (spread {:.4} m)",
            10.0 * faded.snr.log10(),
            angle_error(&masked, az, el).to_degrees(),
            masked.angle_spread_rad.unwrap().to_degrees(),
            masked.tag_used,
            angle_error(&unmasked, az, el).to_degrees(),
            unmasked.angle_spread_rad.unwrap().to_degrees(),
            masked.range.range_m - r,
            masked.range_spread_m.unwrap(),
            unmasked.range.range_m - r,
            unmasked.range_spread_m.unwrap(),
        );
        assert!(faded.snr < 10f64.powf(config.min_peak_snr_db / 10.0));
        // The pair means need no attitude: the same spreads without it.
        let blind = EpochProcessor::new(config.clone())
            .unwrap()
            .process(&y, &Corrections { attitude: None, ..corrections })
            .unwrap();
        assert_eq!(blind.angle_spread_rad, masked.angle_spread_rad);
        assert_eq!(blind.range_spread_m, masked.range_spread_m);
        // Tag 1 keeps its clear channel 1.
        assert_eq!(masked.tag_used, vec![true; TAGS]);
        assert!(angle_error(&masked, az, el) < 0.3f64.to_radians());
        assert!(angle_error(&unmasked, az, el) > 3.0 * angle_error(&masked, az, el));
        assert!(masked.angle_spread_rad.unwrap() < 0.3f64.to_radians());
        assert!(unmasked.angle_spread_rad.unwrap() > 3.0 * masked.angle_spread_rad.unwrap());
        assert!((masked.range.range_m - r).abs() < 0.03);
        assert!(masked.range_spread_m.unwrap() < 0.05);
        assert!(unmasked.range_spread_m.unwrap() > 3.0 * masked.range_spread_m.unwrap());
    }

    #[test]
    fn hover_gives_range_angle_and_the_clock_error() {
        let config = EpochConfig::marvel();
        let mut processor = EpochProcessor::new(config.clone()).unwrap();
        let mut rng = StdRng::seed_from_u64(21);
        let mut scene = Scene::hover([6.0, 18.0, 4.0], 0.0);
        scene.clock_error = 1.5e-6;
        scene.epoch_time_s = 3.7;
        let y = simulate(&config, &scene, &mut rng);
        // Clock error from the peaks at rest.
        let f0 = processor.process(&y, &Corrections::default()).unwrap();
        let rows: Vec<[f64; 4]> = (0..2)
            .flat_map(|j| (0..3).map(move |m| (j, m)))
            .map(|(j, m)| std::array::from_fn(|k| f0.peaks[(j * 4 + k) * 3 + m].frequency_hz))
            .collect();
        let clock = estimate_clock_error(&config.tag_shifts_hz, &config.pairs, &rows).unwrap();
        println!(
            "clock error at 0 dB: {:.4} ppm (true 1.5), sigma {:.4} ppm",
            clock.clock_error * 1e6,
            clock.sigma.unwrap() * 1e6
        );
        // One epoch at 0 dB: sigma ~0.15 ppm (the fit is meant for a few
        // seconds of epochs at rest).
        assert!((clock.clock_error - 1.5e-6).abs() < 4.0 * clock.sigma.unwrap());

        let corrections = Corrections { clock_error: clock.clock_error, ..Default::default() };
        let f = processor.process(&y, &corrections).unwrap();
        let (r, az, el) = truth(&config, &scene);
        println!(
            "hover 0 dB: range {:.4} m (true {r:.4}), timing range {:.3} +- {:.3} m, angle error {:.3} deg, snr {:.2} dB",
            f.range.range_m,
            f.timing_range_m,
            f.timing_range_sigma_m,
            angle_error(&f, az, el).to_degrees(),
            f.snr_db
        );
        assert!((f.range.range_m - r).abs() < 0.03, "{:?}", f.range);
        assert!((f.timing_range_m - r).abs() < 4.0 * f.timing_range_sigma_m + 0.05);
        assert!(angle_error(&f, az, el) < 1f64.to_radians());
        assert!((f.snr_db - 0.0).abs() < 0.5);
        assert!(f.heading.is_none());
        assert!(f.antenna_ranges_m.iter().all(|a| (a - r).abs() < 0.1));
    }

    #[test]
    fn doppler_correction_keeps_the_range_at_speed_and_the_blind_baseline_does_not() {
        let config = EpochConfig::marvel();
        let mut rng = StdRng::seed_from_u64(22);
        let mut scene = Scene::hover([5.0, 25.0, 3.0], 10.0);
        let u = super::super::geometry::normalize(&scene.position).unwrap();
        scene.velocity = u.map(|x| x * 3.0); // 3 m/s away from the controller
        scene.clock_error = -0.8e-6;
        let y = simulate(&config, &scene, &mut rng);
        let corrections =
            Corrections { clock_error: scene.clock_error, velocity: Some(scene.velocity), ..Default::default() };
        let (r, _, _) = truth(&config, &scene);
        let marvel = EpochProcessor::new(config.clone()).unwrap().process(&y, &corrections).unwrap();
        let blind_config = EpochConfig { ignore_doppler: true, ..config.clone() };
        let blind = EpochProcessor::new(blind_config).unwrap().process(&y, &corrections).unwrap();
        println!(
            "3 m/s radial, 10 dB: Marvel range error {:+.3} m (timing {:+.2} m); Doppler-blind {:+.3} m (timing {:+.2} m)",
            marvel.range.range_m - r,
            marvel.timing_range_m - r,
            blind.range.range_m - r,
            blind.timing_range_m - r
        );
        assert!((marvel.range.range_m - r).abs() < 0.05);
        assert!((marvel.timing_range_m - r).abs() < 0.5);
        assert!((blind.range.range_m - r).abs() > 0.3);
        assert!((blind.timing_range_m - r).abs() > 2.0);
    }

    #[test]
    fn heading_from_a_rotating_drone_over_a_full_turn() {
        let config = EpochConfig::marvel();
        let mut processor = EpochProcessor::new(config.clone()).unwrap();
        let mut rng = StdRng::seed_from_u64(23);
        let mut errors = Vec::new();
        for i in 0..12 {
            let yaw = -3.0 + 0.5 * i as f64;
            let rp = roll_pitch_matrix(0.05 * (i % 3) as f64, -0.04 * (i % 2) as f64);
            let mut scene = Scene::hover([-4.0, 15.0, 3.0], 10.0);
            scene.attitude = mat_mul(&rotation_z(yaw), &rp);
            scene.omega_body = mat_vec(&transpose(&scene.attitude), &[0.0, 0.0, 1.2]);
            let y = simulate(&config, &scene, &mut rng);
            // The tracker's attitude: roll/pitch right, yaw unknown (0).
            let corrections =
                Corrections { attitude: Some(rp), omega_body: Some(scene.omega_body), ..Default::default() };
            let f = processor.process(&y, &corrections).unwrap();
            let h = f.heading.expect("rotating");
            // Truth: the yaw at the reference time.
            let yaw_ref = super::super::geometry::yaw_of(&scene.attitude_at(config.reference_time_s()));
            errors.push(super::super::wrap_angle(h.yaw - yaw_ref));
            assert!(errors.last().unwrap().abs() < 0.1, "yaw {yaw}: {h:?}");
        }
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        println!("heading at 1.2 rad/s, 10 dB: yaw rms {:.2} deg over a full turn", rms.to_degrees());
    }

    /// Accuracy at -10 and 0 dB per-sample SNR (26 / 36 dB after
    /// dechirping), moving at 1.8 m/s and yawing at 1 rad/s, 15-35 m;
    /// printed with --nocapture.
    #[test]
    fn accuracy_at_minus_10_and_0_db() {
        let config = EpochConfig::marvel();
        let mut processor = EpochProcessor::new(config.clone()).unwrap();
        let mut rng = StdRng::seed_from_u64(24);
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        for &snr_db in &[-10.0, 0.0] {
            let (mut er, mut et, mut ea, mut ey) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
            let mut wrong_fringe = 0;
            let epochs = 24;
            for i in 0..epochs {
                let yaw = -3.0 + 0.25 * i as f64;
                let x = i as f64 / epochs as f64;
                let mut scene = Scene::hover([8.0 - 16.0 * x, 15.0 + 20.0 * x, 2.0 + 4.0 * x], snr_db);
                scene.velocity = [1.0, -1.5, 0.3];
                scene.attitude = rotation_z(yaw);
                scene.omega_body = [0.0, 0.0, 1.0];
                scene.clock_error = 1e-6;
                scene.epoch_time_s = 10.0 + i as f64;
                let y = simulate(&config, &scene, &mut rng);
                let corrections = Corrections {
                    clock_error: 1e-6,
                    velocity: Some(scene.velocity),
                    attitude: Some(IDENTITY_YAW_FREE),
                    omega_body: Some(scene.omega_body),
                    ..Default::default()
                };
                let f = processor.process(&y, &corrections).unwrap();
                let (r, az, el) = truth(&config, &scene);
                if (f.range.range_m - r).abs() > 1.0 {
                    wrong_fringe += 1;
                } else {
                    er.push(f.range.range_m - r);
                }
                et.push(f.timing_range_m - r);
                ea.push(angle_error(&f, az, el));
                if let Some(h) = f.heading {
                    let yaw_ref = super::super::geometry::yaw_of(&scene.attitude_at(config.reference_time_s()));
                    ey.push(super::super::wrap_angle(h.yaw - yaw_ref));
                }
            }
            println!(
                "{snr_db:+} dB/sample, 1.8 m/s, 1 rad/s: phase range rms {:.3} m ({wrong_fringe} of {epochs} on a wrong fringe), \
                 timing range rms {:.2} m, angle rms {:.2} deg, yaw rms {:.1} deg ({} yaws)",
                rms(&er),
                rms(&et),
                rms(&ea).to_degrees(),
                rms(&ey).to_degrees(),
                ey.len()
            );
            assert!(wrong_fringe <= 3 && rms(&er) < 0.1);
            assert!(rms(&ea) < 3f64.to_radians());
            if snr_db >= 0.0 {
                assert!(wrong_fringe == 0 && rms(&ey) < 10f64.to_radians());
            }
        }
    }

    /// The range modes side by side at 10 dB, hovering with random yaw at
    /// 12-30 m (printed): the paper's reading (all 8 phases coherent, first
    /// path over 0-150 m) against the default.
    #[test]
    fn range_modes_compared() {
        let base = EpochConfig::marvel();
        let modes = [
            ("per-tag, near timing (default)", base.clone()),
            ("pair sums, near timing", EpochConfig { range_coherence: RangeCoherence::PairSums, ..base.clone() }),
            ("across tags, near timing", EpochConfig { range_coherence: RangeCoherence::AcrossTags, ..base.clone() }),
            (
                "across tags, first path 0-150 m (paper)",
                EpochConfig {
                    range_coherence: RangeCoherence::AcrossTags,
                    range_window: RangeWindow::Full,
                    ..base.clone()
                },
            ),
            ("per-tag, first path 0-150 m", EpochConfig { range_window: RangeWindow::Full, ..base.clone() }),
        ];
        let mut rng = StdRng::seed_from_u64(25);
        let scenes: Vec<Scene> = (0..12)
            .map(|i| {
                let mut s = Scene::hover([3.0 - i as f64, 12.0 + 1.5 * i as f64, 2.0 + 0.3 * i as f64], 10.0);
                s.attitude = rotation_z(0.5 * i as f64);
                s.clock_error = 0.7e-6;
                s.epoch_time_s = 5.0 + 3.0 * i as f64;
                s
            })
            .collect();
        let data: Vec<_> = scenes.iter().map(|s| simulate(&base, s, &mut rng)).collect();
        for (name, config) in modes {
            let mut p = EpochProcessor::new(config.clone()).unwrap();
            let errors: Vec<f64> = scenes
                .iter()
                .zip(&data)
                .map(|(s, y)| {
                    let c = Corrections {
                        clock_error: 0.7e-6,
                        velocity: Some([0.0; 3]),
                        epoch_time_s: Some(s.epoch_time_s),
                        ..Default::default()
                    };
                    p.process(y, &c).unwrap().range.range_m - truth(&config, s).0
                })
                .collect();
            let median = {
                let mut a: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
                a.sort_by(f64::total_cmp);
                a[a.len() / 2]
            };
            let max = errors.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            println!("range mode {name}: median |error| {median:.3} m, max {max:.2} m");
            if name.contains("default") {
                assert!(max < 0.05);
            }
        }
    }

    const IDENTITY_YAW_FREE: Mat3 = super::super::geometry::IDENTITY;

    #[test]
    fn rejects_bad_shapes_and_configs() {
        let config = EpochConfig::marvel();
        let mut p = EpochProcessor::new(config.clone()).unwrap();
        let y = vec![num_complex::Complex32::new(0.0, 0.0); 10];
        assert_eq!(p.process(&y, &Corrections::default()).unwrap_err().kind(), "shape");
        assert!(EpochProcessor::new(EpochConfig { pairs: [(0, 1), (1, 2)], ..config.clone() }).is_err());
        assert!(EpochProcessor::new(EpochConfig { calibration_rad: vec![0.0; 5], ..config.clone() }).is_err());
        assert!(EpochProcessor::new(EpochConfig { channels_hz: [915e6, 915e6], ..config }).is_err());
    }
}
