use num_complex::Complex64;

use crate::error::{Error, Result};
use crate::SPEED_OF_LIGHT;

/// The channel of one path of length `d` (m) at each frequency (Hz):
/// `a exp(−j 2π f d / c)` — the convention of docs/formats.md §5 (`a > 0`).
pub fn path_channel(frequencies_hz: &[f64], path_length_m: f64, amplitude: f64) -> Vec<Complex64> {
    frequencies_hz
        .iter()
        .map(|f| Complex64::from_polar(amplitude, -std::f64::consts::TAU * f * path_length_m / SPEED_OF_LIGHT))
        .collect()
}

/// Per-(rx, subcarrier) complex correction that maps measured tag channels
/// to the docs/formats.md §5 convention (thesis ch. 4.3: "a one-time calibration
/// with a known RFID location in order to eliminate other over-the-wire
/// hardware channels").
///
/// The measured tag channel is `Ĥ(r, f) = G(r, f) Γ h(r, f)` with `G` the
/// hardware response of tx chain, rx chain and cables (gain and phase
/// ripple, delay; it also holds the symbol timing's linear phase), `Γ` the
/// tag's differential reflection coefficient (including the state polarity
/// sign) and `h` the propagation channel. With a tag at a known position,
/// `h_ref` is known from geometry, so `C(r, f) = h_ref(r, f) / Ĥ_cal(r, f)`
/// and `C Ĥ = h` for any later position of the same tag, as long as the
/// hardware and the timing reference do not change.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// Receive antennas (rows).
    pub antennas: usize,
    /// Active subcarriers (columns).
    pub subcarriers: usize,
    /// `C(r, f)`, row-major `r · subcarriers + f`.
    pub correction: Vec<Complex64>,
}

impl Calibration {
    /// A calibration from one or several measured tag channels of a tag at a
    /// known position (each `antennas × subcarriers`, row-major) and the
    /// reference channel `h_ref` there (same layout; e.g. [`path_channel`]
    /// per rx). Several replies are averaged after aligning each one's
    /// polarity with the first (as [`super::Ema`] does), which divides the
    /// noise of the correction by their number.
    ///
    /// Errors: [`Error::Shape`]; [`Error::BadCalibration`] naming the rx and
    /// subcarrier where the averaged measurement is zero or non-finite or
    /// the reference non-finite.
    pub fn from_measurements(
        measured: &[&[Complex64]],
        reference: &[Complex64],
        antennas: usize,
        subcarriers: usize,
    ) -> Result<Self> {
        let size = antennas * subcarriers;
        if size == 0 || reference.len() != size {
            return Err(Error::Shape(format!(
                "reference has {} values for {antennas} rx × {subcarriers} subcarriers",
                reference.len()
            )));
        }
        if measured.is_empty() {
            return Err(Error::BadCalibration("no calibration reply".into()));
        }
        if let Some(m) = measured.iter().find(|m| m.len() != size) {
            return Err(Error::Shape(format!("a calibration reply has {} values, expected {size}", m.len())));
        }
        let mut mean = vec![Complex64::new(0.0, 0.0); size];
        let first = measured[0];
        for m in measured {
            let overlap: f64 = m
                .iter()
                .zip(first)
                .filter(|(a, b)| a.is_finite() && b.is_finite())
                .map(|(a, b)| (a * b.conj()).re)
                .sum();
            let sign = if overlap < 0.0 { -1.0 } else { 1.0 };
            mean.iter_mut().zip(m.iter()).for_each(|(s, v)| *s += v * sign);
        }
        let count = measured.len() as f64;
        let mut correction = Vec::with_capacity(size);
        for (i, (m, r)) in mean.iter().zip(reference).enumerate() {
            let m = m / count;
            let c = r / m;
            if !(m.norm() > 0.0 && c.is_finite()) {
                return Err(Error::BadCalibration(format!(
                    "rx {} subcarrier {}: measured {m}, reference {r}",
                    i / subcarriers,
                    i % subcarriers
                )));
            }
            correction.push(c);
        }
        Ok(Self { antennas, subcarriers, correction })
    }

    /// Applies the correction in place to a tag channel
    /// (`antennas × subcarriers`, row-major): `h ← C h`.
    pub fn apply(&self, h: &mut [Complex64]) -> Result<()> {
        if h.len() != self.correction.len() {
            return Err(Error::Shape(format!(
                "channel has {} values, calibration is {} rx × {} subcarriers",
                h.len(),
                self.antennas,
                self.subcarriers
            )));
        }
        h.iter_mut().zip(&self.correction).for_each(|(v, c)| *v *= c);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_the_hardware_response_at_another_position() {
        let f: Vec<f64> = (0..19).map(|k| 865e6 + 5e6 * k as f64).collect();
        let hardware: Vec<Complex64> =
            (0..2 * 19).map(|i| Complex64::from_polar(0.3 + 0.01 * i as f64, 0.4 * i as f64 - 1.0)).collect();
        let gamma = Complex64::from_polar(0.2, 2.5);
        let distances_cal = [2.0, 2.4];
        let distances_new = [3.1, 2.2];
        let channel =
            |d: &[f64; 2]| -> Vec<Complex64> { d.iter().flat_map(|&d| path_channel(&f, d, 1.0 / d)).collect() };
        let measure = |h: &[Complex64], sign: f64| -> Vec<Complex64> {
            h.iter().zip(&hardware).map(|(h, g)| h * g * gamma * sign).collect()
        };
        let reference = channel(&distances_cal);
        let a = measure(&reference, 1.0);
        let b = measure(&reference, -1.0); // opposite polarity: aligned before averaging
        let cal = Calibration::from_measurements(&[&a, &b], &reference, 2, 19).unwrap();
        let truth = channel(&distances_new);
        let mut h = measure(&truth, 1.0);
        cal.apply(&mut h).unwrap();
        for (x, y) in h.iter().zip(&truth) {
            assert!((x - y).norm() < 1e-12);
        }
        // Phase slope of the calibrated channel gives the path length back.
        let slope = (h[18] * h[0].conj()).arg() / (f[18] - f[0]);
        let implied = -slope * SPEED_OF_LIGHT / std::f64::consts::TAU;
        let wrap = SPEED_OF_LIGHT / (f[18] - f[0]);
        assert!(((implied - 3.1) / wrap - ((implied - 3.1) / wrap).round()).abs() < 1e-9);
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        let r = vec![Complex64::new(1.0, 0.0); 4];
        let zero = vec![Complex64::new(0.0, 0.0); 4];
        let e = Calibration::from_measurements(&[&zero], &r, 2, 2).unwrap_err();
        assert!(matches!(&e, Error::BadCalibration(m) if m.starts_with("rx 0 subcarrier 0")), "{e}");
        assert!(matches!(Calibration::from_measurements(&[&r[..3]], &r, 2, 2), Err(Error::Shape(_))));
        assert!(matches!(Calibration::from_measurements(&[], &r, 2, 2), Err(Error::BadCalibration(_))));
        let cal = Calibration::from_measurements(&[&r], &r, 2, 2).unwrap();
        assert!(cal.apply(&mut [Complex64::new(1.0, 0.0)]).is_err());
    }
}
