//! TurboTrack's parameter table (also its comparison variants:
//! `gaussian-pf`, `uniform-pf`, `ellipse-intersection`, `rfind`). Candidate
//! extraction's fields are named `candidate_<field>`.
//!
//! Defaults are `TurboTrackParams::default()`'s. Adding a parameter: the
//! field and its default in `turbotrack.rs`, then one row here. The
//! likelihood, initial sampling and proposal are not parameters: the method
//! name chooses them (`track::make`).

use super::turbotrack::TurboTrackParams;
use crate::model::wideband::CandidateWeighting;
use crate::params::{choice, float, integer, optional_float, Bound, Range, Table};

/// `(0, 1]`: the likelihood temper κ.
const TEMPER: Range = Range { low: Bound::Exclusive(0.0), high: Bound::Inclusive(1.0) };

/// `(0, inf]`: a level that `inf` switches off.
const POSITIVE_OR_OFF: Range = Range { low: Bound::Exclusive(0.0), high: Bound::Inclusive(f64::INFINITY) };

/// The table of TurboTrack and its variants.
pub fn turbotrack_table() -> Table<TurboTrackParams> {
    Table::new(
        "turbotrack",
        vec![
            integer("particles", Range::at_least(1.0), "particles", "number of particles N", |p| p.particles, |p, v| p.particles = v),
            float(
                "transition_sigma_m",
                Range::POSITIVE,
                "m",
                "1-sigma per axis of the random-walk step Sigma_v over one reference_interval_s (thesis ch. 6: 5 mm)",
                |p| p.transition_sigma_m,
                |p, v| p.transition_sigma_m = v,
            ),
            float(
                "reference_interval_s",
                Range::POSITIVE,
                "s",
                "frame interval the step sigma refers to; the variance scales with the actual interval",
                |p| p.reference_interval_s,
                |p, v| p.reference_interval_s = v,
            ),
            float(
                "static_sigma_m",
                Range::POSITIVE,
                "m",
                "1-sigma per axis of a static-mode particle's random-walk step over one reference_interval_s: particles switch between moving (transition_sigma_m) and static, and the weights choose, so a tag at rest is averaged over many frames",
                |p| p.static_sigma_m,
                |p, v| p.static_sigma_m = v,
            ),
            float(
                "static_entry_probability",
                Range { low: Bound::Inclusive(0.0), high: Bound::Exclusive(1.0) },
                "",
                "probability that a moving particle turns static over one reference_interval_s; 0: every particle moving (the thesis's single random walk)",
                |p| p.static_entry_probability,
                |p, v| p.static_entry_probability = v,
            ),
            float(
                "static_exit_probability",
                Range { low: Bound::Exclusive(0.0), high: Bound::Inclusive(1.0) },
                "",
                "probability that a static particle turns moving over one reference_interval_s (a static lineage lasts only while the weights keep choosing it)",
                |p| p.static_exit_probability,
                |p, v| p.static_exit_probability = v,
            ),
            float(
                "calibration_sigma_m",
                Range::NON_NEGATIVE,
                "m",
                "1-sigma calibration residual of each receiver's path sum: a bias no number of frames averages away, added to the reported covariance as sigma^2 (J^T J)^-1; 0: none",
                |p| p.calibration_sigma_m,
                |p, v| p.calibration_sigma_m = v,
            ),
            float(
                "resample_threshold",
                Range::UNIT,
                "",
                "resample when the effective sample size falls below this fraction of N",
                |p| p.resample_threshold,
                |p, v| p.resample_threshold = v,
            ),
            float(
                "perimeter_threshold_m",
                Range::POSITIVE,
                "m",
                "gaussian-pf only: perimeter threshold T of the thesis's initial pruning (doubled up to 3 times when no tuple survives); turbotrack and uniform-pf test each tuple's chi-square against outlier_chi2 instead",
                |p| p.perimeter_threshold_m,
                |p, v| p.perimeter_threshold_m = v,
            ),
            integer(
                "max_initial_components",
                Range::at_least(1.0),
                "components",
                "largest number of initial mixture components kept (by weight)",
                |p| p.max_initial_components,
                |p, v| p.max_initial_components = v,
            ),
            float(
                "intersection_tolerance_m",
                Range::NON_NEGATIVE,
                "m",
                "tangency tolerance of the intersection routine",
                |p| p.intersection_tolerance_m,
                |p, v| p.intersection_tolerance_m = v,
            ),
            optional_float(
                "distance_sigma_m",
                Range::POSITIVE,
                "m",
                "fixed 1-sigma path-length error sigma_w; none: each frame's own estimate",
                |p| p.distance_sigma_m,
                |p, v| p.distance_sigma_m = v,
            ),
            float("weight_floor", Range::UNIT, "", "mixture weight of comb teeth outside the kept candidates", |p| p.weight_floor, |p, v| p.weight_floor = v),
            float(
                "outlier_chi2",
                Range::POSITIVE,
                "",
                "a frame is an outlier when even the best particle's chi-square over the receivers exceeds this",
                |p| p.outlier_chi2,
                |p, v| p.outlier_chi2 = v,
            ),
            float(
                "outlier_jump_m",
                Range::NON_NEGATIVE,
                "m",
                "... or when the fix jumps farther than this plus max_speed_m_s times the interval",
                |p| p.outlier_jump_m,
                |p, v| p.outlier_jump_m = v,
            ),
            float("max_speed_m_s", Range::NON_NEGATIVE, "m/s", "largest plausible tag speed (for the jump test only)", |p| p.max_speed_m_s, |p, v| p.max_speed_m_s = v),
            integer(
                "max_consecutive_outliers",
                Range::at_least(1.0),
                "frames",
                "start over after this many consecutive outlier frames",
                |p| p.max_consecutive_outliers,
                |p, v| p.max_consecutive_outliers = v,
            ),
            float("reinit_gap_s", Range::POSITIVE, "s", "start over after a gap between frames longer than this", |p| p.reinit_gap_s, |p, v| p.reinit_gap_s = v),
            float(
                "region_margin_m",
                Range::NON_NEGATIVE,
                "m",
                "particles farther than this outside the region are impossible",
                |p| p.region_margin_m,
                |p, v| p.region_margin_m = v,
            ),
            integer(
                "history_frames",
                Range::NON_NEGATIVE,
                "frames",
                "frames of particle ancestry kept for the backtracked MAP trajectory",
                |p| p.history_frames,
                |p, v| p.history_frames = v,
            ),
            float(
                "velocity_window_s",
                Range::POSITIVE,
                "s",
                "velocity is the slope of the estimates over this window",
                |p| p.velocity_window_s,
                |p, v| p.velocity_window_s = v,
            ),
            integer("seed", Range::NON_NEGATIVE, "", "seed of the sampler's random numbers", |p| p.seed, |p, v| p.seed = v),
            float(
                "rfind_window_s",
                Range::POSITIVE,
                "s",
                "acquisition window of the RFind baseline (a static tag is assumed over it)",
                |p| p.rfind_window_s,
                |p, v| p.rfind_window_s = v,
            ),
            float(
                "lobe_switch_nats",
                POSITIVE_OR_OFF,
                "nats",
                "lobe test: move the particles to another lobe when its accumulated evidence against theirs exceeds this (inf: never)",
                |p| p.lobe_switch_nats,
                |p, v| p.lobe_switch_nats = v,
            ),
            float(
                "lobe_floor_nats",
                Range::NON_NEGATIVE,
                "nats",
                "lobe test: an alternative lobe's evidence never sinks below minus this",
                |p| p.lobe_floor_nats,
                |p, v| p.lobe_floor_nats = v,
            ),
            float(
                "far_lobe_search_s",
                POSITIVE_OR_OFF,
                "s",
                "far lobes: repeat the initial tuple search this often and test its fits as alternatives (inf: only the first frame's)",
                |p| p.far_lobe_search_s,
                |p, v| p.far_lobe_search_s = v,
            ),
            float(
                "static_average_s",
                Range::NON_NEGATIVE,
                "s",
                "resting average: while the tag rests the estimate is the fit of the frames' coherent average, forgotten with this time constant (0: the particles' mode)",
                |p| p.static_average_s,
                |p, v| p.static_average_s = v,
            ),
            float(
                "lobe_frame_cap_nats",
                Range::POSITIVE,
                "nats",
                "lobe test: one frame changes a lobe's evidence by at most this",
                |p| p.lobe_frame_cap_nats,
                |p, v| p.lobe_frame_cap_nats = v,
            ),
            float(
                "candidate_min_relative_weight",
                Range::UNIT,
                "",
                "keep candidates whose envelope is at least this fraction of the peak (the N of eq. 5.1)",
                |p| p.candidates.min_relative_weight,
                |p, v| p.candidates.min_relative_weight = v,
            ),
            integer(
                "candidate_max_candidates",
                Range::at_least(1.0),
                "candidates",
                "largest number of candidates kept per receive antenna",
                |p| p.candidates.max_candidates,
                |p, v| p.candidates.max_candidates = v,
            ),
            float(
                "candidate_weight_exponent",
                Range::NON_NEGATIVE,
                "",
                "exponent p of the amplitude weighting |B(d_n)|^p",
                |p| p.candidates.weight_exponent,
                |p, v| p.candidates.weight_exponent = v,
            ),
            float(
                "candidate_likelihood_temper",
                TEMPER,
                "",
                "temper kappa of the likelihood weighting",
                |p| p.candidates.likelihood_temper,
                |p, v| p.candidates.likelihood_temper = v,
            ),
            choice(
                "candidate_weighting",
                "weights w(n) of eq. 5.1: the thesis's FFT amplitude, or the single-path profile likelihood",
                &[("amplitude", CandidateWeighting::Amplitude), ("likelihood", CandidateWeighting::Likelihood)],
                |p| p.candidates.weighting,
                |p, v| p.candidates.weighting = v,
            ),
            float(
                "candidate_min_sigma_m",
                Range::POSITIVE,
                "m",
                "smallest 1-sigma distance error sigma_w reported (residual calibration error floors it)",
                |p| p.candidates.min_sigma_m,
                |p, v| p.candidates.min_sigma_m = v,
            ),
            float(
                "candidate_max_sigma_m",
                Range::POSITIVE,
                "m",
                "largest sigma_w reported",
                |p| p.candidates.max_sigma_m,
                |p, v| p.candidates.max_sigma_m = v,
            ),
        ],
    )
}
