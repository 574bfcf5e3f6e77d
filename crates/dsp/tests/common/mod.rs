//! A small seeded simulator of one reply window per rx antenna, for the
//! crate's integration tests and benchmarks (the full IQ simulator is
//! `scattertrack.sim.iq` in Python; this one is independent of it).
//!
//! Model (steady state of back-to-back symbols, exact in the frequency
//! domain): per rx `a` and FFT bin `k` (RF frequency `f_k`),
//! `y = IDFT(X · G_a · (L_a + s(t) Γ T_a))` with `L_a` the direct tx → rx
//! leakage (one path, amplitude `leakage_gain / d`), `T_a` the tag's
//! bistatic path `exp(−j2π f d/c) / (d₁ d₂)`, `Γ` the differential
//! reflection coefficient, `G_a` a hardware response (gain, phase ripple,
//! fractional delay), `s(t) ∈ [0, 1]` the chip level with a linear ramp of
//! `transition_samples` at each change, plus white complex Gaussian noise
//! that sets the tag's per-sample SNR.

#![allow(dead_code)]

use num_complex::{Complex32, Complex64};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use scattertrack_dsp::backscatter::{reply_chips, Encoding};
use scattertrack_dsp::ofdm::{KnownSymbol, OfdmConfig};
use scattertrack_dsp::SPEED_OF_LIGHT;

pub fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[derive(Clone, Debug)]
pub struct Reply {
    pub config: OfdmConfig,
    pub symbol: KnownSymbol,
    pub encoding: Encoding,
    pub trext: bool,
    pub bits: Vec<u8>,
    pub tx: [f64; 3],
    pub rx: Vec<[f64; 3]>,
    pub tag: [f64; 3],
    /// Differential reflection coefficient Γ (reflective − non-reflective).
    pub gamma: Complex64,
    /// Leakage amplitude factor over free space.
    pub leakage_gain: f64,
    /// Per-rx hardware delay, samples.
    pub hardware_delay_samples: Vec<f64>,
    /// Relative gain ripple across the band.
    pub ripple: f64,
    /// Tag SNR per sample, dB (`f64::INFINITY`: no noise).
    pub snr_db: f64,
    /// True BLF over nominal.
    pub blf_scale: f64,
    /// Reply start (first chip) after the window start, s.
    pub reply_start_s: f64,
    pub window_samples: usize,
    /// Index of the window's first sample in the tx stream, mod N.
    pub tx_phase: usize,
    /// Duration of a state change, samples.
    pub transition_samples: f64,
    /// Level of the tag outside its reply.
    pub idle_level: f64,
    /// No reply at all in the window.
    pub silent: bool,
    pub seed: u64,
}

impl Reply {
    /// The thesis set-up (ch. 6): 100 MHz, N = 20, BLF 40 kHz, FM0, four rx
    /// 40 cm apart, a tag about 1.5 m away, a 300 µs window.
    pub fn paper(seed: u64) -> Self {
        let config = OfdmConfig::new(100e6, 20, 915e6, 40e3).unwrap();
        let symbol = KnownSymbol::generate(20, 17).unwrap();
        Self {
            config,
            symbol,
            encoding: Encoding::Fm0,
            trext: false,
            bits: vec![1, 0, 1, 1, 0, 0, 1, 0, 1, 1, 1, 0, 0, 1, 0, 1],
            tx: [0.0, 0.0, 0.0],
            rx: vec![[0.4, 0.0, 0.0], [0.8, 0.0, 0.0], [1.2, 0.0, 0.0], [1.6, 0.0, 0.0]],
            tag: [0.7, 1.4, 0.3],
            gamma: Complex64::from_polar(0.3, 1.1),
            leakage_gain: 30.0,
            hardware_delay_samples: vec![2.2, 3.7, 1.1, 2.9],
            ripple: 0.2,
            snr_db: 0.0,
            blf_scale: 1.0,
            reply_start_s: 25e-6,
            window_samples: 30_000,
            tx_phase: 7,
            transition_samples: 10.0,
            idle_level: 0.0,
            silent: false,
            seed,
        }
    }

    pub fn chips(&self) -> Vec<u8> {
        reply_chips(self.encoding, self.trext, &self.bits).unwrap()
    }

    /// RF frequency of FFT bin `k`.
    fn bin_frequency(&self, k: usize) -> f64 {
        let n = self.config.subcarriers as i64;
        let signed = if (k as i64) < n - n / 2 { k as i64 } else { k as i64 - n };
        self.config.centre_hz + signed as f64 * self.config.bandwidth_hz / n as f64
    }

    fn signed_bin(&self, k: usize) -> f64 {
        let n = self.config.subcarriers as i64;
        (if (k as i64) < n - n / 2 { k as i64 } else { k as i64 - n }) as f64
    }

    /// Hardware response `G_a` at FFT bin `k`.
    pub fn hardware(&self, a: usize, k: usize) -> Complex64 {
        let n = self.config.subcarriers as f64;
        let x = self.signed_bin(k) / n;
        let gain = (1.0 + 0.25 * a as f64) * (1.0 + self.ripple * (7.0 * x + a as f64).cos());
        let phase = 0.4 * (5.0 * x + 0.3 * a as f64).sin() + a as f64;
        let delay = -std::f64::consts::TAU * self.signed_bin(k) * self.hardware_delay_samples[a] / n;
        Complex64::from_polar(gain, phase + delay)
    }

    /// The tag channel at FFT bin `k` in the docs/formats.md §5 convention.
    pub fn tag_channel_bin(&self, a: usize, k: usize, tag: &[f64; 3]) -> Complex64 {
        let (d1, d2) = (distance(&self.tx, tag), distance(tag, &self.rx[a]));
        Complex64::from_polar(
            1.0 / (d1 * d2),
            -std::f64::consts::TAU * self.bin_frequency(k) * (d1 + d2) / SPEED_OF_LIGHT,
        )
    }

    /// docs/formats.md §5 tag channel, `rx × active subcarriers`, ascending.
    pub fn true_tag_channel(&self, tag: &[f64; 3]) -> Vec<Complex64> {
        let bins = self.config.active_bins();
        (0..self.rx.len()).flat_map(|a| bins.iter().map(move |&k| self.tag_channel_bin(a, k, tag))).collect()
    }

    /// What the DSP measures before calibration (`G Γ T`, FFT timing at the
    /// tx symbol boundary), `rx × active subcarriers`.
    pub fn raw_tag_channel(&self) -> Vec<Complex64> {
        let bins = self.config.active_bins();
        (0..self.rx.len())
            .flat_map(|a| {
                bins.iter().map(move |&k| self.hardware(a, k) * self.gamma * self.tag_channel_bin(a, k, &self.tag))
            })
            .collect()
    }

    /// Signed bins of the active subcarriers (ascending), for the timing's
    /// linear phase.
    pub fn signed_active_bins(&self) -> Vec<f64> {
        self.config.signed_bins().into_iter().map(|k| k as f64).collect()
    }

    /// Per-sample complex noise standard deviation for the configured SNR.
    pub fn noise_sigma(&self) -> f64 {
        if !self.snr_db.is_finite() {
            return 0.0;
        }
        let n = self.config.subcarriers;
        let power: f64 = (0..self.rx.len())
            .map(|a| {
                (1..n)
                    .map(|k| (self.hardware(a, k) * self.gamma * self.tag_channel_bin(a, k, &self.tag)).norm_sqr())
                    .sum::<f64>()
                    / n as f64
            })
            .sum::<f64>()
            / self.rx.len() as f64;
        (power / 10f64.powf(self.snr_db / 10.0)).sqrt()
    }

    /// Chip level at time `t` seconds after the window start (with ramps).
    fn level(&self, chips: &[u8], t: f64) -> f64 {
        if self.silent {
            return self.idle_level;
        }
        let chip_s = 1.0 / (2.0 * self.config.blf_hz * self.blf_scale);
        let ramp = self.transition_samples / self.config.bandwidth_hz;
        let at = |x: f64| -> f64 {
            let c = ((x - self.reply_start_s) / chip_s).floor();
            if c < 0.0 || c >= chips.len() as f64 {
                self.idle_level
            } else {
                chips[c as usize] as f64
            }
        };
        if ramp <= 0.0 {
            return at(t);
        }
        // Linear ramp: average of the hard waveform over [t − ramp/2, t + ramp/2].
        let steps = 8;
        (0..steps).map(|i| at(t - ramp / 2.0 + ramp * (i as f64 + 0.5) / steps as f64)).sum::<f64>() / steps as f64
    }

    /// One window per rx antenna.
    pub fn windows(&self) -> Vec<Vec<Complex32>> {
        let n = self.config.subcarriers;
        let chips = self.chips();
        let sigma = self.noise_sigma();
        let mut rng = StdRng::seed_from_u64(self.seed);
        let normal = Normal::new(0.0, (sigma * sigma / 2.0).sqrt().max(1e-300)).unwrap();
        let levels: Vec<f64> =
            (0..self.window_samples).map(|i| self.level(&chips, i as f64 / self.config.bandwidth_hz)).collect();
        (0..self.rx.len())
            .map(|a| {
                let d = distance(&self.tx, &self.rx[a]);
                let idft = |spectrum: &dyn Fn(usize) -> Complex64| -> Vec<Complex64> {
                    (0..n)
                        .map(|t| {
                            (0..n)
                                .map(|k| {
                                    self.symbol.frequency[k]
                                        * spectrum(k)
                                        * Complex64::from_polar(1.0, std::f64::consts::TAU * (k * t) as f64 / n as f64)
                                })
                                .sum::<Complex64>()
                                / (n as f64).sqrt()
                        })
                        .collect()
                };
                let leak = idft(&|k| {
                    self.hardware(a, k)
                        * Complex64::from_polar(
                            self.leakage_gain / d,
                            -std::f64::consts::TAU * self.bin_frequency(k) * d / SPEED_OF_LIGHT,
                        )
                });
                let tag = idft(&|k| self.hardware(a, k) * self.gamma * self.tag_channel_bin(a, k, &self.tag));
                (0..self.window_samples)
                    .map(|i| {
                        let p = (i + self.tx_phase) % n;
                        let mut v = leak[p] + tag[p] * levels[i];
                        if sigma > 0.0 {
                            v += Complex64::new(normal.sample(&mut rng), normal.sample(&mut rng));
                        }
                        Complex32::new(v.re as f32, v.im as f32)
                    })
                    .collect()
            })
            .collect()
    }
}
