//! Channel phases at a common reference time (docs/marvel.md section 7,
//! step 3; paper eq. 3).
//!
//! Eq. 3 and the centre reference. The dechirped sample at time `t'` into
//! the chirp carries the channel phase at the chirp's instantaneous
//! frequency: with `c(t - tau)` received, `arg(y conj(c)) =
//! -2 pi (f_c - BW/2 + (BW/T) t') tau + 2 pi BW tau^2/(2T) + ...` where
//! `f_c = f_j + s_k/2` is the received channel's centre. The peak's phase is
//! the (weighted) sum over all the chirp's frequencies, eq. 3; referred to
//! `t' = T/2` (the chirp centre, [`super::Peak::amplitude_centre`]) it is
//! exactly the phase at `f_c`, `-2 pi f_c tau + 2 pi cfo_k t + phi`, at the
//! time `t_j + T/2` — whatever the split of the tone's frequency into delay,
//! CFO and Doppler. (Referred to the start, the phase belongs to
//! `f_c - BW/2` and its variance is four times larger.)
//!
//! Between the two chirps of an epoch the phase keeps turning at
//! `cfo_k + f_D,k` (docs/marvel.md section 6: `d psi / dt = 2 pi (cfo_k +
//! f_D,k)`, since `f_D = -f dtau/dt`). [`refer_phase`] removes that ramp to
//! bring every (channel, tag, antenna) to one reference time; without it the
//! second channel's phases are off by `2 pi (cfo + f_D) T`, about 1 rad at
//! 3 m/s, which biases the range by ~0.9 m (the Doppler-blind baseline's
//! error, paper Fig. 9).

use std::f64::consts::TAU;

/// Angles wrap to `(-pi, pi]`: the workspace's one function for it, in the core.
pub use scattertrack_core::angle::wrap_angle;

/// Phase `phase_rad` observed at time `from_s` moved to `to_s` (s) by
/// removing a constant frequency offset's ramp, `phase - 2 pi offset (from -
/// to)`, wrapped (rad). `offset_hz` is the sum of the known offsets
/// (`cfo_k + f_D,k`).
pub fn refer_phase(phase_rad: f64, from_s: f64, to_s: f64, offset_hz: f64) -> f64 {
    wrap_angle(phase_rad - TAU * offset_hz * (from_s - to_s))
}

/// What [`channel_phase`] removes from a chirp's centre-referred phase.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PhaseCorrection {
    /// The tag's CFO `cfo_k = eps s_k`, Hz.
    pub cfo_hz: f64,
    /// The tag's Doppler `f_D,k` on this channel (translational + rotational),
    /// Hz; 0 for the Doppler-blind baseline.
    pub doppler_hz: f64,
    /// Absolute time of the epoch's time origin, s (the recording time of
    /// the first chirp's start). `Some`: the CFO's whole phase
    /// `2 pi cfo_k t` (docs/marvel.md section 6 writes it with the absolute
    /// `t`) is removed, which makes tags comparable with each other;
    /// `None`: only its ramp within the epoch.
    pub epoch_time_s: Option<f64>,
}

/// The channel phase (eq. 3) of one (channel, tag, antenna) at the epoch's
/// reference time: `centre_phase_rad` is `arg` of the peak referred to the
/// chirp centre, observed at `chirp_centre_s` (s, from the epoch origin);
/// `reference_s` is the common reference time (s, from the epoch origin);
/// `calibration_rad` the receive chain's known offset `theta_m(f)`.
///
/// `theta = arg - theta_m - 2 pi f_D (t_c - t_ref) - 2 pi cfo (t_c - t_ref)`,
/// or with `epoch_time_s = Some(t0)` the CFO term is `2 pi cfo (t0 + t_c)`
/// (the whole clock phase). Wrapped to (-pi, pi].
pub fn channel_phase(
    centre_phase_rad: f64,
    chirp_centre_s: f64,
    reference_s: f64,
    calibration_rad: f64,
    correction: &PhaseCorrection,
) -> f64 {
    let doppler = TAU * correction.doppler_hz * (chirp_centre_s - reference_s);
    let cfo = match correction.epoch_time_s {
        // Reduce cfo * t modulo one cycle before scaling: cfo t reaches
        // thousands of cycles in a long recording.
        Some(t0) => TAU * (correction.cfo_hz * (t0 + chirp_centre_s)).rem_euclid(1.0),
        None => TAU * correction.cfo_hz * (chirp_centre_s - reference_s),
    };
    wrap_angle(centre_phase_rad - calibration_rad - doppler - cfo)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_removal_brings_both_chirps_to_one_time() {
        // A phase turning at cfo + f_D: psi(t) = psi0 + 2 pi (cfo + fd) t.
        let (cfo, fd, psi0) = (3.2, -17.5, 0.8);
        let t_ref = 8.192e-3;
        let psi = |t: f64| wrap_angle(psi0 + TAU * (cfo + fd) * t);
        let c = PhaseCorrection { cfo_hz: cfo, doppler_hz: fd, epoch_time_s: None };
        for &tc in &[4.096e-3, 12.288e-3] {
            let theta = channel_phase(psi(tc), tc, t_ref, 0.0, &c);
            assert!(wrap_angle(theta - psi(t_ref)).abs() < 1e-9);
            assert!(wrap_angle(refer_phase(psi(tc), tc, t_ref, cfo + fd) - psi(t_ref)).abs() < 1e-9);
        }
        // Absolute CFO removal at a late epoch leaves psi0 + the Doppler
        // ramp to t_ref only.
        let t0 = 1234.5;
        let psi_abs = |t: f64| wrap_angle(psi0 + TAU * (cfo * (t0 + t)).rem_euclid(1.0) + TAU * fd * t);
        let c = PhaseCorrection { epoch_time_s: Some(t0), ..c };
        let theta = channel_phase(psi_abs(12.288e-3), 12.288e-3, t_ref, 0.5, &c);
        assert!(wrap_angle(theta - (psi0 + TAU * fd * t_ref - 0.5)).abs() < 1e-6);
    }
}
