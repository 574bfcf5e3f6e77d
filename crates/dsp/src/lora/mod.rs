//! Marvel pose sensing from LoRa backscatter (docs/marvel.md sections 1-7;
//! paper sec. III, eqs. 1-8). Pure functions and reusable processors: no
//! estimator code, no I/O.
//!
//! Contract:
//! - Samples: the channelised baseband of one (channel, tag, antenna) chirp,
//!   `N = 2^SF` samples at `fs = BW` starting at the chirp start; any
//!   [`Sample`] type, `Complex32` (`cf32` recordings) or `Complex64`.
//!   Everything else is `f64`, SI units (Hz, s, m, rad, m/s, rad/s).
//! - Signal model (docs/marvel.md section 6): `y = a exp(i psi) c(t - t_j -
//!   tau)`, `psi = -2 pi (f_j + s_k/2) tau + 2 pi cfo_k t + phi_tag +
//!   theta_m`, `tau = (|p_k - rho_tx| + |p_k - rho_m|)/c0`; after
//!   dechirping a tone at `cfo_k + f_D,k - (BW/T) tau`, with the Doppler
//!   `f_D,k = -(f/c0) d(path)/dt`.
//! - Phase sign: channel phases decrease with path length (`-2 pi f tau`);
//!   every step (range profile, steering vector, ramp removal) follows it.
//! - Angles wrap to (-pi, pi] with [`wrap_angle`]; directions `u(az, el)`
//!   point from the controller to the drone (docs/marvel.md section 1).
//!
//! Steps (one file each):
//! 1. [`chirp`]: [`ChirpConfig`], the up/downchirp.
//! 2. [`peak`]: [`PeakFinder`] — dechirp, FFT, interpolated + Newton-refined
//!    tone frequency, the complex amplitude at the chirp start and centre,
//!    SNR and Cramer-Rao sigmas.
//! 3. [`doppler`]: pair mean / half difference (eqs. 2, 7), CFO from rest
//!    ([`estimate_clock_error`]), translational/rotational Doppler (eq. 1).
//! 4. [`phase`]: channel phase at the epoch's reference time (eq. 3).
//! 5. [`range`]: delay profile over arbitrary frequencies, first path.
//! 6. [`music`](mod@music): virtual measurement matrix, MUSIC for any 3D array (eqs.
//!    5-6), harmonic-mean (paper) or circular combination.
//! 7. [`heading`]: yaw from the pairs' rotational Doppler (eqs. 7-8 in 3D).
//! 8. [`epoch`]: [`EpochProcessor`], the whole chain for one epoch.
//!
//! [`geometry`] holds the 3-vector/rotation helpers (`[f64; 3]`, row-major
//! `[[f64; 3]; 3]`).

pub mod chirp;
pub mod doppler;
pub mod epoch;
pub mod geometry;
pub mod heading;
pub mod music;
pub mod peak;
pub mod phase;
pub mod range;

pub use chirp::{downchirp, upchirp, ChirpConfig};
pub use doppler::{
    cfo_hz, delay_frequency_hz, delay_from_frequency_s, estimate_clock_error, pair_half_difference, pair_mean,
    rotational_doppler_hz, tag_doppler_hz, translational_doppler_hz, ClockEstimate,
};
pub use epoch::{Corrections, EpochConfig, EpochFeatures, EpochProcessor, RangeCoherence, RangeWindow};
pub use geometry::{Mat3, Vec3};
pub use heading::{
    pair_coefficients, predicted_difference_hz, solve_yaw, HeadingConfig, HeadingEstimate, PairObservation, YawGeometry,
};
pub use music::{combine_angles, music, AngleCombine, ArrayGeometry, ArrayKind, MusicConfig, MusicEstimate};
pub use peak::{tone_crlb, Peak, PeakFinder, PeakOptions, Sample};
pub use phase::{channel_phase, refer_phase, wrap_angle, PhaseCorrection};
pub use range::{delay_profile, estimate_range, group_deviations_m, PhaseGroup, RangeConfig, RangeEstimate, RangeSelect};
