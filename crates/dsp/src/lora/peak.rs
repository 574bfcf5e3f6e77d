//! Dechirp, FFT peak and sub-bin tone estimate (docs/marvel.md section 7,
//! step 1; paper sec. III-A, III-B).
//!
//! After dechirping (`y[n] conj(c[n])`) a tag's reply is a tone
//! `z[n] = A exp(i (phi0 + 2 pi f_peak n / fs))` with
//! `f_peak = cfo_k + f_D,k - (BW/T) tau` (docs/marvel.md section 6): a few
//! hertz, while the FFT bin is `BW / 2^SF` = 122 Hz. The estimate is
//! therefore the maximum-likelihood one, the argmax of the DTFT magnitude
//! `|Z(f)|`: the FFT finds the bin, Jacobsen's three-bin interpolator with
//! Candan's bias correction puts the start within a small fraction of a bin,
//! and safeguarded Newton steps on `|Z(f)|^2` (analytic first and second
//! derivatives) converge to the DTFT peak. The ML estimate reaches the
//! Cramer-Rao bound above the threshold SNR, which the tests check at
//! -10 dB per sample.

use std::sync::Arc;

use num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};

use super::chirp::ChirpConfig;
use crate::error::{Error, Result};

/// A raw sample type the peak finder accepts: `Complex32` (the recordings'
/// `cf32`) or `Complex64` (simulators). All arithmetic is `f64`.
pub trait Sample: Copy {
    fn to_c64(self) -> Complex64;
}

impl Sample for Complex32 {
    fn to_c64(self) -> Complex64 {
        Complex64::new(self.re as f64, self.im as f64)
    }
}

impl Sample for Complex64 {
    fn to_c64(self) -> Complex64 {
        self
    }
}

/// Options of [`PeakFinder`].
#[derive(Debug, Clone, PartialEq)]
pub struct PeakOptions {
    /// Search the peak only where `|f| <= search_hz` (Hz); `None`: the whole
    /// band `[-BW/2, BW/2)`. A window makes a false noise peak less likely at
    /// very low SNR when the tone is known to be near 0 Hz.
    pub search_hz: Option<f64>,
    /// Newton iterations at most (each one pass over the chirp).
    pub max_iterations: usize,
    /// Stop when a Newton step is below this, Hz.
    pub tolerance_hz: f64,
}

impl Default for PeakOptions {
    fn default() -> Self {
        Self { search_hz: None, max_iterations: 8, tolerance_hz: 1e-6 }
    }
}

/// One dechirped tone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Peak {
    /// Tone frequency, Hz, signed around 0 (`[-BW/2, BW/2)`).
    pub frequency_hz: f64,
    /// Least-squares complex amplitude of the tone referred to the chirp
    /// start (`n = 0`): its phase is the dechirped phase at `t = t_j`.
    /// Amplitude in the samples' units (per sample).
    pub amplitude: Complex64,
    /// The same tone referred to the chirp centre (`t = t_j + T/2`,
    /// `n = N/2`). Its phase is the channel phase at the chirp's centre
    /// frequency `f_j + s_k/2` at that time (eq. 3, see [`super::phase`]),
    /// and it is (nearly) uncorrelated with the frequency error, so its
    /// variance is a quarter of the start-referred phase's.
    pub amplitude_centre: Complex64,
    /// Estimated per-sample SNR (linear): `|A|^2 / sigma^2`.
    pub snr: f64,
    /// Estimated per-sample noise power `sigma^2` (samples' units squared),
    /// from the median FFT bin power.
    pub noise_power: f64,
    /// Cramer-Rao standard deviation of the frequency at the estimated SNR,
    /// Hz: `sqrt(6 / ((2 pi)^2 snr N (N^2 - 1))) fs`.
    pub frequency_sigma_hz: f64,
    /// Cramer-Rao standard deviation of the centre-referred phase at the
    /// estimated SNR, rad: `sqrt(1 / (2 N snr))`.
    pub phase_sigma_rad: f64,
    /// FFT bin of the coarse peak (0..N).
    pub bin: usize,
    /// Newton iterations used.
    pub iterations: usize,
}

impl Peak {
    /// Processing (post-dechirp) SNR in dB: `10 log10(N snr)`, the per-sample
    /// SNR plus the `2^SF` dechirp gain (36 dB at SF 12).
    pub fn processing_snr_db(&self, samples: usize) -> f64 {
        10.0 * (samples as f64 * self.snr).max(1e-30).log10()
    }
}

/// Cramer-Rao bounds of a single complex tone in white complex Gaussian noise
/// (`N` samples, per-sample SNR `snr = A^2 / sigma^2`, `sigma^2` the total
/// complex noise variance): `(sigma_f` Hz at sample rate `fs`,
/// `sigma_phase` rad at the centre, `sigma_phase` rad at `n = 0)`.
///
/// From the Fisher information of `(omega, phi)`,
/// `2 snr [[sum n^2, sum n], [sum n, N]]`: `var(omega) = 6 / (snr N (N^2-1))`
/// rad^2/sample^2, `var(phi_0) = (2N-1) / (snr N (N+1))` (about `2/(N snr)`)
/// and at the centre `1 / (2 N snr)`.
pub fn tone_crlb(samples: usize, snr: f64, sample_rate_hz: f64) -> (f64, f64, f64) {
    let n = samples as f64;
    let var_omega = 6.0 / (snr * n * (n * n - 1.0));
    let sigma_f = var_omega.sqrt() * sample_rate_hz / std::f64::consts::TAU;
    let sigma_centre = (1.0 / (2.0 * n * snr)).sqrt();
    let sigma_start = ((2.0 * n - 1.0) / (snr * n * (n + 1.0))).sqrt();
    (sigma_f, sigma_centre, sigma_start)
}

/// Dechirp + FFT + sub-bin peak for one chirp, with the FFT plan, the
/// downchirp and all buffers allocated once (one per worker; `process` is
/// allocation-free).
pub struct PeakFinder {
    chirp: ChirpConfig,
    options: PeakOptions,
    down: Vec<Complex64>,
    fft: Arc<dyn Fft<f64>>,
    dechirped: Vec<Complex64>,
    spectrum: Vec<Complex64>,
    scratch: Vec<Complex64>,
    power: Vec<f64>,
}

impl PeakFinder {
    pub fn new(chirp: ChirpConfig, options: PeakOptions) -> Result<Self> {
        if let Some(s) = options.search_hz {
            if !(s > 0.0 && s.is_finite()) {
                return Err(Error::BadConfig(format!("peak search window must be > 0 Hz, got {s}")));
            }
        }
        if options.tolerance_hz.is_nan() || options.tolerance_hz <= 0.0 {
            return Err(Error::BadConfig("peak tolerance must be > 0 Hz".into()));
        }
        let n = chirp.samples();
        let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
        let zero = Complex64::new(0.0, 0.0);
        Ok(Self {
            chirp,
            options,
            down: chirp.downchirp(),
            scratch: vec![zero; fft.get_inplace_scratch_len()],
            fft,
            dechirped: vec![zero; n],
            spectrum: vec![zero; n],
            power: vec![0.0; n],
        })
    }

    pub fn chirp(&self) -> &ChirpConfig {
        &self.chirp
    }

    /// The dechirped samples of the last [`PeakFinder::process`] call.
    pub fn dechirped(&self) -> &[Complex64] {
        &self.dechirped
    }

    /// The tone of one received chirp: `samples` are exactly `N = 2^SF`
    /// samples starting at the chirp start `t_j` (baseband, `fs = BW`).
    ///
    /// Errors: [`Error::Shape`] for another length, [`Error::NonFinite`] for
    /// NaN/inf samples.
    pub fn process<S: Sample>(&mut self, samples: &[S]) -> Result<Peak> {
        let n = self.chirp.samples();
        if samples.len() != n {
            return Err(Error::Shape(format!("a chirp is {n} samples, got {}", samples.len())));
        }
        for ((z, s), d) in self.dechirped.iter_mut().zip(samples).zip(&self.down) {
            let s = s.to_c64();
            if !(s.re.is_finite() && s.im.is_finite()) {
                return Err(Error::NonFinite("chirp samples".into()));
            }
            *z = s * d;
        }
        self.spectrum.copy_from_slice(&self.dechirped);
        self.fft.process_with_scratch(&mut self.spectrum, &mut self.scratch);
        for (p, x) in self.power.iter_mut().zip(&self.spectrum) {
            *p = x.norm_sqr();
        }

        // Coarse peak within the search window (bins in FFT order).
        let fs = self.chirp.sample_rate_hz();
        let bin_hz = fs / n as f64;
        let signed = |k: usize| if k >= n / 2 { k as f64 - n as f64 } else { k as f64 };
        let mut best = (0usize, -1.0f64);
        for (k, &p) in self.power.iter().enumerate() {
            let inside = self.options.search_hz.is_none_or(|w| (signed(k) * bin_hz).abs() <= w);
            if inside && p > best.1 {
                best = (k, p);
            }
        }
        let k = best.0;
        // Jacobsen's interpolator with Candan's correction: nearly unbiased
        // for a rectangular window, so Newton starts well inside the lobe.
        let (xm, x0, xp) = (self.spectrum[(k + n - 1) % n], self.spectrum[k], self.spectrum[(k + 1) % n]);
        let denominator = x0 * 2.0 - xm - xp;
        let mut delta = if denominator.norm() > 0.0 { ((xm - xp) / denominator).re } else { 0.0 };
        let pi_n = std::f64::consts::PI / n as f64;
        delta *= pi_n.tan() / pi_n;
        let delta = delta.clamp(-0.5, 0.5);
        let mut omega = std::f64::consts::TAU * (signed(k) + delta) / n as f64;

        // Newton on g(omega) = |Z(omega)|^2 with the index centred on
        // c = (N-1)/2 (better conditioned sums); step safeguarded to a
        // quarter bin and required to increase g.
        let centre = (n as f64 - 1.0) / 2.0;
        let max_step = std::f64::consts::TAU / n as f64 / 4.0;
        let tolerance = std::f64::consts::TAU * self.options.tolerance_hz / fs;
        let mut iterations = 0;
        let (mut s0, _, _) = dtft_sums(&self.dechirped, omega, centre, false);
        for _ in 0..self.options.max_iterations {
            iterations += 1;
            let (_, s1, s2) = dtft_sums(&self.dechirped, omega, centre, true);
            let g = s0.norm_sqr();
            // g' = 2 Im(conj(S0) S1), g'' = 2 (|S1|^2 - Re(conj(S0) S2)).
            let d1 = 2.0 * (s0.conj() * s1).im;
            let d2 = 2.0 * (s1.norm_sqr() - (s0.conj() * s2).re);
            let mut step = if d2 < 0.0 { -d1 / d2 } else { max_step * d1.signum() };
            step = step.clamp(-max_step, max_step);
            let mut accepted = false;
            for _ in 0..20 {
                let (t0, _, _) = dtft_sums(&self.dechirped, omega + step, centre, false);
                if t0.norm_sqr() >= g {
                    omega += step;
                    s0 = t0;
                    accepted = true;
                    break;
                }
                step *= 0.5;
            }
            if !accepted || step.abs() < tolerance {
                break;
            }
        }

        // LS amplitude at the refined frequency: Z_c(omega) / N is the tone
        // amplitude at the centre index c; move it to n = 0 and n = N/2.
        let a_c = s0 / n as f64;
        let amplitude = a_c * Complex64::from_polar(1.0, -omega * centre);
        let amplitude_centre = a_c * Complex64::from_polar(1.0, omega * (n as f64 / 2.0 - centre));

        // Noise: the median of N bin powers of complex Gaussian noise is
        // ln 2 times its mean N sigma^2 (unnormalised FFT); the peak bins
        // barely move a median of 4096.
        let mid = n / 2;
        let (_, median, _) = self.power.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        let noise_power = (*median / std::f64::consts::LN_2 / n as f64).max(f64::MIN_POSITIVE);
        // E|A_hat|^2 = |A|^2 + sigma^2 / N.
        let signal = (a_c.norm_sqr() - noise_power / n as f64).max(f64::MIN_POSITIVE);
        let snr = signal / noise_power;
        let (frequency_sigma_hz, phase_sigma_rad, _) = tone_crlb(n, snr, fs);
        let frequency_hz = omega / std::f64::consts::TAU * fs;
        Ok(Peak {
            frequency_hz,
            amplitude,
            amplitude_centre,
            snr,
            noise_power,
            frequency_sigma_hz,
            phase_sigma_rad,
            bin: k,
            iterations,
        })
    }
}

/// `S_p = sum_n (n - c)^p z[n] exp(-i omega (n - c))` for p = 0, 1, 2 (the
/// DTFT and its scaled derivatives: `Z' = -i S1`, `Z'' = -S2`), by a phasor
/// recurrence (one complex multiply per sample instead of a sin/cos; the
/// rounding error after 4096 steps is ~1e-12).
fn dtft_sums(z: &[Complex64], omega: f64, centre: f64, derivatives: bool) -> (Complex64, Complex64, Complex64) {
    let step = Complex64::from_polar(1.0, -omega);
    let mut phasor = Complex64::from_polar(1.0, omega * centre);
    let (mut s0, mut s1, mut s2) = (Complex64::new(0.0, 0.0), Complex64::new(0.0, 0.0), Complex64::new(0.0, 0.0));
    if derivatives {
        for (i, &x) in z.iter().enumerate() {
            let m = i as f64 - centre;
            let v = x * phasor;
            s0 += v;
            s1 += v * m;
            s2 += v * (m * m);
            phasor *= step;
        }
    } else {
        for &x in z {
            s0 += x * phasor;
            phasor *= step;
        }
    }
    (s0, s1, s2)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// One received chirp per the signal model (docs/marvel.md section 6):
    /// `A exp(i (phase + 2 pi offset t)) c(t - tau)` plus complex white
    /// noise of total variance `noise_power`, sampled at `t = n / fs`.
    pub(crate) fn received_chirp(
        chirp: &ChirpConfig,
        amplitude: f64,
        phase: f64,
        offset_hz: f64,
        tau_s: f64,
        noise_power: f64,
        rng: &mut StdRng,
    ) -> Vec<Complex32> {
        let fs = chirp.sample_rate_hz();
        let normal = Normal::new(0.0, (noise_power / 2.0).sqrt().max(1e-300)).unwrap();
        (0..chirp.samples())
            .map(|n| {
                let t = n as f64 / fs;
                // The chirp's phase polynomial continued before its start:
                // the dechirped tone is then exact. (Whatever precedes the
                // chirp in a recording touches only the first tau*fs < 1
                // samples, an O(1/N) effect.)
                let c = Complex64::from_polar(1.0, std::f64::consts::TAU * chirp.phase_cycles(t - tau_s));
                let y = c * Complex64::from_polar(amplitude, phase + std::f64::consts::TAU * offset_hz * t);
                let w = if noise_power > 0.0 {
                    Complex64::new(normal.sample(rng), normal.sample(rng))
                } else {
                    Complex64::new(0.0, 0.0)
                };
                let v = y + w;
                Complex32::new(v.re as f32, v.im as f32)
            })
            .collect()
    }

    fn wrap(x: f64) -> f64 {
        super::super::wrap_angle(x)
    }

    #[test]
    fn noise_free_tones_are_exact_anywhere_in_the_band() {
        let chirp = ChirpConfig::marvel();
        let mut finder = PeakFinder::new(chirp, PeakOptions::default()).unwrap();
        let mut rng = StdRng::seed_from_u64(1);
        for &f in &[0.0, 3.3, -7.9, 61.0, -61.04, 1234.5, -200_000.0] {
            let y = received_chirp(&chirp, 0.7, 0.4, f, 0.0, 0.0, &mut rng);
            let p = finder.process(&y).unwrap();
            assert!((p.frequency_hz - f).abs() < 1e-4, "{f}: {}", p.frequency_hz);
            assert!((p.amplitude.norm() - 0.7).abs() < 1e-5);
            assert!(wrap(p.amplitude.arg() - 0.4).abs() < 1e-5, "{f}: {}", p.amplitude.arg());
            let centre_phase = 0.4 + std::f64::consts::TAU * f * chirp.duration_s() / 2.0;
            assert!(wrap(p.amplitude_centre.arg() - centre_phase).abs() < 1e-5);
        }
        assert!(finder.process(&vec![Complex32::new(0.0, 0.0); 100]).is_err());
        let mut bad = vec![Complex32::new(0.0, 0.0); 4096];
        bad[3] = Complex32::new(f32::NAN, 0.0);
        assert_eq!(finder.process(&bad).unwrap_err().kind(), "non-finite");
    }

    #[test]
    fn a_delay_becomes_the_tone_minus_bw_over_t_tau_with_the_centre_frequency_phase() {
        // Docs section 6: f_peak = -(BW/T) tau; and (eq. 3) the centre-referred
        // phase is the channel phase at the centre frequency, i.e. the
        // carrier term alone: the chirp's own -pi BW tau start offset
        // cancels at t = T/2.
        let chirp = ChirpConfig::marvel();
        let mut finder = PeakFinder::new(chirp, PeakOptions::default()).unwrap();
        let mut rng = StdRng::seed_from_u64(2);
        for &tau in &[0.0, 60e-9, 213.7e-9, 1.3e-6] {
            let y = received_chirp(&chirp, 1.0, -1.1, 0.0, tau, 0.0, &mut rng);
            let p = finder.process(&y).unwrap();
            let expected = -chirp.chirp_rate_hz_per_s() * tau;
            assert!((p.frequency_hz - expected).abs() < 1e-3, "{tau}: {} vs {expected}", p.frequency_hz);
            let tiny = std::f64::consts::PI * chirp.chirp_rate_hz_per_s() * tau * tau; // 2 pi BW tau^2/(2T)
            assert!(wrap(p.amplitude_centre.arg() - (-1.1 + tiny)).abs() < 1e-4, "{tau}: {}", p.amplitude_centre.arg());
        }
    }

    /// Monte Carlo at -10 dB per-sample SNR, SF 12: frequency and phase
    /// errors against the Cramer-Rao bound (printed with --nocapture).
    #[test]
    fn reaches_the_cramer_rao_bound_at_minus_10_db_per_sample() {
        let chirp = ChirpConfig::marvel();
        let n = chirp.samples();
        let mut finder = PeakFinder::new(chirp, PeakOptions::default()).unwrap();
        let mut rng = StdRng::seed_from_u64(3);
        let snr = 0.1; // -10 dB per sample: 26 dB after the 36 dB dechirp gain
        let trials = 300;
        let (mut ef, mut ec, mut es, mut snr_est) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..trials {
            let f: f64 = rng.random_range(-6.0..6.0);
            let phase: f64 = rng.random_range(-3.0..3.0);
            let y = received_chirp(&chirp, 1.0, phase, f, 0.0, 1.0 / snr, &mut rng);
            let p = finder.process(&y).unwrap();
            ef.push(p.frequency_hz - f);
            ec.push(wrap(p.amplitude_centre.arg() - (phase + std::f64::consts::TAU * f * chirp.duration_s() / 2.0)));
            es.push(wrap(p.amplitude.arg() - phase));
            snr_est.push(p.snr);
        }
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let (crlb_f, crlb_c, crlb_s) = tone_crlb(n, snr, chirp.sample_rate_hz());
        let mean_snr = snr_est.iter().sum::<f64>() / trials as f64;
        println!(
            "peak @ -10 dB/sample, SF12: freq rms {:.3} Hz (CRLB {:.3}), centre phase rms {:.4} rad (CRLB {:.4}), \
             start phase rms {:.4} rad (CRLB {:.4}), snr estimate {:.4} (true 0.1)",
            rms(&ef),
            crlb_f,
            rms(&ec),
            crlb_c,
            rms(&es),
            crlb_s,
            mean_snr
        );
        assert!(rms(&ef) < 1.25 * crlb_f && rms(&ef) > 0.75 * crlb_f);
        assert!(rms(&ec) < 1.25 * crlb_c && rms(&ec) > 0.75 * crlb_c);
        assert!(rms(&es) < 1.25 * crlb_s && rms(&es) > 0.75 * crlb_s);
        assert!((mean_snr / snr - 1.0).abs() < 0.1);
        let bias = ef.iter().sum::<f64>() / trials as f64;
        assert!(bias.abs() < 4.0 * crlb_f / (trials as f64).sqrt());
    }

    #[test]
    fn search_window_restricts_the_peak() {
        // A strong interferer 50 kHz away (its sidelobes near 0 Hz are
        // ~1e-3) and the wanted weak tone at 30 Hz.
        let chirp = ChirpConfig::marvel();
        let mut rng = StdRng::seed_from_u64(4);
        let mut y = received_chirp(&chirp, 1.0, 0.0, 50_030.0, 0.0, 0.0, &mut rng);
        let weak = received_chirp(&chirp, 0.2, 0.0, 30.0, 0.0, 0.0, &mut rng);
        for (a, b) in y.iter_mut().zip(&weak) {
            *a += b;
        }
        let mut all = PeakFinder::new(chirp, PeakOptions::default()).unwrap();
        assert!((all.process(&y).unwrap().frequency_hz - 50_030.0).abs() < 1.0);
        let mut near = PeakFinder::new(chirp, PeakOptions { search_hz: Some(1000.0), ..Default::default() }).unwrap();
        assert!((near.process(&y).unwrap().frequency_hz - 30.0).abs() < 1.0);
    }
}
