//! The LoRa CSS chirp (docs/marvel.md sections 5 and 6; paper sec. III-A).

use num_complex::{Complex32, Complex64};

use crate::error::{Error, Result};

/// A LoRa chirp: spreading factor `SF` (6..=12, paper sec. III-A) and
/// bandwidth `BW` (Hz). Duration `T = 2^SF / BW` (s); sampled at
/// `fs = BW` (the receiver's channelised baseband rate), so one chirp is
/// exactly `N = 2^SF` samples and the FFT bin after dechirping is
/// `BW / 2^SF` Hz (122 Hz for SF 12, 500 kHz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChirpConfig {
    spreading_factor: u32,
    bandwidth_hz: f64,
}

impl ChirpConfig {
    /// Validates `SF` in 6..=12 (the LoRa range; SF sets the dechirp gain
    /// `2^SF`) and a positive, finite bandwidth (LoRa uses 125, 250 or
    /// 500 kHz; any value is accepted because nothing here depends on it
    /// beyond scaling).
    pub fn new(spreading_factor: u32, bandwidth_hz: f64) -> Result<Self> {
        if !(6..=12).contains(&spreading_factor) {
            return Err(Error::BadConfig(format!("LoRa spreading factor must be 6..=12, got {spreading_factor}")));
        }
        if !(bandwidth_hz > 0.0 && bandwidth_hz.is_finite()) {
            return Err(Error::BadConfig(format!("chirp bandwidth must be > 0 Hz, got {bandwidth_hz}")));
        }
        Ok(Self { spreading_factor, bandwidth_hz })
    }

    /// The Marvel default: SF 12, BW 500 kHz, `T = 8.192 ms`
    /// (docs/marvel.md section 5).
    pub fn marvel() -> Self {
        Self { spreading_factor: 12, bandwidth_hz: 500e3 }
    }

    pub fn spreading_factor(&self) -> u32 {
        self.spreading_factor
    }

    /// `BW`, Hz.
    pub fn bandwidth_hz(&self) -> f64 {
        self.bandwidth_hz
    }

    /// Samples per chirp, `N = 2^SF`.
    pub fn samples(&self) -> usize {
        1 << self.spreading_factor
    }

    /// Complex sample rate `fs = BW`, Hz.
    pub fn sample_rate_hz(&self) -> f64 {
        self.bandwidth_hz
    }

    /// Chirp duration `T = 2^SF / BW`, s.
    pub fn duration_s(&self) -> f64 {
        self.samples() as f64 / self.bandwidth_hz
    }

    /// FFT bin after dechirping, `BW / 2^SF = 1 / T`, Hz.
    pub fn bin_hz(&self) -> f64 {
        self.bandwidth_hz / self.samples() as f64
    }

    /// Chirp rate `BW / T`, Hz/s: a delay `tau` (s) turns into the dechirped
    /// tone `-(BW/T) tau` (docs/marvel.md section 6).
    pub fn chirp_rate_hz_per_s(&self) -> f64 {
        self.bandwidth_hz / self.duration_s()
    }

    /// The upchirp's phase at time `t` (s, from the chirp start), cycles:
    /// `-BW/2 t + BW/(2T) t^2` (docs/marvel.md section 6). Defined for every
    /// `t`; the chirp itself lives on `0 <= t < T`.
    pub fn phase_cycles(&self, t: f64) -> f64 {
        let bw = self.bandwidth_hz;
        -0.5 * bw * t + 0.5 * bw / self.duration_s() * t * t
    }

    /// `c(t) = exp(i 2 pi (-BW/2 t + BW/(2T) t^2))` for `0 <= t < T`, zero
    /// outside (a single chirp, docs/marvel.md section 6).
    pub fn upchirp_at(&self, t: f64) -> Complex64 {
        if !(0.0..self.duration_s()).contains(&t) {
            return Complex64::new(0.0, 0.0);
        }
        let cycles = self.phase_cycles(t);
        Complex64::from_polar(1.0, std::f64::consts::TAU * (cycles - cycles.round()))
    }

    /// The sampled upchirp `c[n] = c(n / fs)`, `n = 0..2^SF`: instantaneous
    /// frequency rising linearly from `-BW/2` to `+BW/2` (Hz, baseband).
    ///
    /// At `fs = BW` the phase is `2 pi (-n/2 + n^2/(2N))` cycles; it is
    /// reduced modulo one cycle in exact arithmetic before the `sin/cos`
    /// (`n^2 / 2N` is exact in `f64` because `N` is a power of two), so the
    /// reference has no phase error growing along the chirp.
    pub fn upchirp(&self) -> Vec<Complex64> {
        let n_total = self.samples() as u64;
        (0..n_total)
            .map(|n| {
                // 2N * cycles = n^2 - N n, an exact integer; reduce modulo 2N.
                let twice_n = 2 * n_total;
                let numerator = (n * n + twice_n * n_total - n_total * n) % twice_n;
                let cycles = numerator as f64 / twice_n as f64;
                Complex64::from_polar(1.0, std::f64::consts::TAU * cycles)
            })
            .collect()
    }

    /// The matching downchirp, `conj(c[n])`: multiplying a received upchirp
    /// by it ("dechirping", paper sec. III-A) turns the chirp into a tone.
    pub fn downchirp(&self) -> Vec<Complex64> {
        self.upchirp().into_iter().map(|c| c.conj()).collect()
    }
}

/// The sampled LoRa upchirp (see [`ChirpConfig::upchirp`]); errors for SF
/// outside 6..=12 or a bad bandwidth.
pub fn upchirp(spreading_factor: u32, bandwidth_hz: f64) -> Result<Vec<Complex64>> {
    Ok(ChirpConfig::new(spreading_factor, bandwidth_hz)?.upchirp())
}

/// The sampled LoRa downchirp `conj(c[n])` (see [`ChirpConfig::downchirp`]).
pub fn downchirp(spreading_factor: u32, bandwidth_hz: f64) -> Result<Vec<Complex64>> {
    Ok(ChirpConfig::new(spreading_factor, bandwidth_hz)?.downchirp())
}

/// `Complex64` samples narrowed to `cf32` (the recordings' sample type), for
/// simulators and tests.
pub fn to_cf32(samples: &[Complex64]) -> Vec<Complex32> {
    samples.iter().map(|c| Complex32::new(c.re as f32, c.im as f32)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validates_the_spreading_factor_and_bandwidth() {
        assert!(ChirpConfig::new(5, 500e3).is_err());
        assert!(ChirpConfig::new(13, 500e3).is_err());
        assert!(ChirpConfig::new(12, 0.0).is_err());
        assert!(ChirpConfig::new(12, f64::NAN).is_err());
        let c = ChirpConfig::new(12, 500e3).unwrap();
        assert_eq!(c.samples(), 4096);
        assert!((c.duration_s() - 8.192e-3).abs() < 1e-15);
        assert!((c.bin_hz() - 122.0703125).abs() < 1e-9);
    }

    #[test]
    fn sampled_chirp_matches_the_continuous_model_and_sweeps_the_band() {
        for sf in 6..=12 {
            let c = ChirpConfig::new(sf, 125e3).unwrap();
            let up = c.upchirp();
            let fs = c.sample_rate_hz();
            for (n, v) in up.iter().enumerate().step_by(7) {
                let direct = c.upchirp_at(n as f64 / fs);
                assert!((v - direct).norm() < 1e-9, "sf {sf} n {n}");
            }
            // Instantaneous frequency (phase step) rises linearly by BW/N per
            // sample from -BW/2.
            let n = c.samples();
            for k in [1usize, n / 4, n / 2, n - 1] {
                let step = (up[k] * up[k - 1].conj()).arg() / std::f64::consts::TAU * fs;
                let expected = -c.bandwidth_hz() / 2.0 + c.bin_hz() * (k as f64 - 0.5);
                let wrapped = (step - expected + fs / 2.0).rem_euclid(fs) - fs / 2.0;
                assert!(wrapped.abs() < 1e-6, "sf {sf} k {k}: {step} vs {expected}");
            }
            // Dechirping an undelayed upchirp gives DC exactly.
            let down = c.downchirp();
            assert!(up.iter().zip(&down).all(|(u, d)| (u * d - Complex64::new(1.0, 0.0)).norm() < 1e-12));
        }
    }
}
