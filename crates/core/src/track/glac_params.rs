//! GLAC's parameter table: every name `GlacParams` is set by, from Python,
//! the CLI and the docs (`docs/parameters.md` is generated from it).
//!
//! One row per parameter: name, range, unit, one-line description, and how
//! to read and write the field. Defaults are `GlacParams::default()`'s.
//! Adding a parameter: add the field (and its default) to `GlacParams` in
//! `glac.rs`, then one row here; `validate()` there keeps the checks that
//! involve several fields.

use super::glac::{GlacParams, Inference, Likelihood};
use crate::model::MotionModel;
use crate::params::{boolean, choice, float, integer, optional_float, Bound, Range, Table};

/// The motion model's kind, as a choice (the process noise is `q`).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    ConstantVelocity,
    RandomWalk,
}

fn motion_q(p: &GlacParams) -> f64 {
    match p.motion {
        MotionModel::ConstantVelocity { q } | MotionModel::RandomWalk { q } => q,
    }
}

fn set_motion(p: &mut GlacParams, kind: Motion, q: f64) {
    p.motion = match kind {
        Motion::ConstantVelocity => MotionModel::ConstantVelocity { q },
        Motion::RandomWalk => MotionModel::RandomWalk { q },
    };
}

fn motion_kind(p: &GlacParams) -> Motion {
    if p.motion.has_velocity() {
        Motion::ConstantVelocity
    } else {
        Motion::RandomWalk
    }
}

/// `[0, 1)`: the quick-stop threshold is a normalised likelihood below 1.
const BELOW_ONE: Range = Range { low: Bound::Inclusive(0.0), high: Bound::Exclusive(1.0) };

/// The table of GLAC and its variants (`glac`, `glac-no-velocity`, ...).
pub fn glac_table() -> Table<GlacParams> {
    Table::new(
        "glac",
        vec![
            // Keeps the model's kind: `motion` and `q` may come in either order.
            float(
                "q",
                Range::POSITIVE,
                "m^2/s^3",
                "process noise: white-acceleration PSD of the constant-velocity model (eq. 3); with motion=random-walk the position diffusion, m^2/s",
                motion_q,
                |p, q| set_motion(p, motion_kind(p), q),
            ),
            choice(
                "motion",
                "motion model; the -no-velocity methods switch to a random walk with q = 0.009 m^2/s unless given random-walk here",
                &[("constant-velocity", Motion::ConstantVelocity), ("random-walk", Motion::RandomWalk)],
                motion_kind,
                |p, kind| set_motion(p, kind, motion_q(p)),
            ),
            choice(
                "inference",
                "nearest-neighbour pruning + quick stop (fast), unpruned (naive) or trilaterated read groups (synchronous); normally set by the method name",
                &[("fast", Inference::Fast), ("naive", Inference::Naive), ("synchronous", Inference::Synchronous)],
                |p| p.inference,
                |p, v| p.inference = v,
            ),
            choice(
                "likelihood",
                "per-read likelihood: the EKF's N(nu; 0, S) (innovation) or the paper's eqs. 12-13 literally (paper, needs manoeuvre_q=none)",
                &[("innovation", Likelihood::Innovation), ("paper", Likelihood::Paper)],
                |p| p.likelihood,
                |p, v| p.likelihood = v,
            ),
            optional_float(
                "phase_noise_rad",
                Range::POSITIVE,
                "rad",
                "1-sigma white phase noise; none: the scene's phase_noise_rad (0.1 if absent)",
                |p| p.phase_noise_rad,
                |p, v| p.phase_noise_rad = v,
            ),
            // On a real reader: phase_noise_rad the read-to-read noise of a
            // static tag (about 0.015 rad), this the rest of the error budget
            // (realistic-3d-arm, bench/run.py: the log's 0.07 rad as white
            // noise gives a 284 mm median, 0.015 + 0.12 rad 19.3 mm).
            float(
                "phase_wander_rad",
                Range::NON_NEGATIVE,
                "rad",
                "1-sigma of the phase error correlated in time on each antenna (wander, calibration, multipath); 0: all white",
                |p| p.phase_wander_rad,
                |p, v| p.phase_wander_rad = v,
            ),
            float("phase_wander_s", Range::POSITIVE, "s", "correlation time tau of that error", |p| p.phase_wander_s, |p, v| p.phase_wander_s = v),
            float(
                "bias_sigma_rad",
                Range::NON_NEGATIVE,
                "rad",
                "1-sigma of a slow per-antenna phase bias (wander, calibration residual, multipath; real readers 0.05-0.1 rad), estimated per hypothesis with bias_state, else added to the reported covariance; 0 = off",
                |p| p.bias_sigma_rad,
                |p, v| p.bias_sigma_rad = v,
            ),
            boolean(
                "bias_state",
                "estimate that bias per antenna in every hypothesis as an AR(1) state (fast inference)",
                |p| p.bias_state,
                |p, v| p.bias_state = v,
            ),
            float("bias_time_s", Range::POSITIVE, "s", "correlation time of the bias", |p| p.bias_time_s, |p, v| p.bias_time_s = v),
            float(
                "hop_bias_sigma_rad",
                Range::NON_NEGATIVE,
                "rad",
                "1-sigma of the bias share drawn afresh when an antenna's read is on another channel than its previous one (per-channel calibration residual, multipath); 0: the bias ignores hops",
                |p| p.hop_bias_sigma_rad,
                |p, v| p.hop_bias_sigma_rad = v,
            ),
            optional_float(
                "bank_sigma_rad",
                Range::POSITIVE,
                "rad",
                "a second bias_sigma_rad run beside it (glac, bias_state): the tracker whose reads' accumulated evidence is larger is reported; none: one tracker",
                |p| p.bank_sigma_rad,
                |p, v| p.bank_sigma_rad = v,
            ),
            optional_float(
                "bank_time_s",
                Range::POSITIVE,
                "s",
                "bias correlation time of the bank's second tracker; none: bias_time_s",
                |p| p.bank_time_s,
                |p, v| p.bank_time_s = v,
            ),
            float(
                "bank_switch_nats",
                Range::POSITIVE,
                "nats",
                "the bias-level bank reports another tracker once its log evidence leads by this much",
                |p| p.bank_switch_nats,
                |p, v| p.bank_switch_nats = v,
            ),
            float(
                "bank_drop_nats",
                Range::POSITIVE,
                "nats",
                "the bias-level bank drops a tracker whose log evidence is this far behind the best",
                |p| p.bank_drop_nats,
                |p, v| p.bank_drop_nats = v,
            ),
            float(
                "init_window_s",
                Range::POSITIVE,
                "s",
                "collect reads at least this long before initial state pruning",
                |p| p.init_window_s,
                |p, v| p.init_window_s = v,
            ),
            float(
                "init_max_window_s",
                Range::POSITIVE,
                "s",
                "give up waiting for every antenna to be read after this long",
                |p| p.init_max_window_s,
                |p, v| p.init_max_window_s = v,
            ),
            float(
                "init_position_sigma_m",
                Range::POSITIVE,
                "m",
                "initial 1-sigma position uncertainty of a hypothesis",
                |p| p.init_position_sigma_m,
                |p, v| p.init_position_sigma_m = v,
            ),
            float(
                "init_velocity_sigma_m_s",
                Range::POSITIVE,
                "m/s",
                "initial 1-sigma velocity uncertainty of a hypothesis",
                |p| p.init_velocity_sigma_m_s,
                |p, v| p.init_velocity_sigma_m_s = v,
            ),
            float(
                "quick_stop",
                BELOW_ONE,
                "",
                "quick-stop threshold l_th: hypotheses whose normalised likelihood falls below it are removed",
                |p| p.quick_stop,
                |p, v| p.quick_stop = v,
            ),
            float(
                "weight_temperature",
                Range::at_least(1.0),
                "-",
                "temperature T of the hypothesis weights in the reported covariance: competitors count as if the evidence against them were T times weaker (correlated phase errors overcount it); 1 = the plain posterior",
                |p| p.weight_temperature,
                |p, v| p.weight_temperature = v,
            ),
            float(
                "gate_sigmas",
                Range::POSITIVE,
                "sigma",
                "recovery gate (the paper's 3 sigma_v; 2.5 by default, which lets fewer outliers through): a read whose innovation exceeds it is replaced by the prediction",
                |p| p.gate_sigmas,
                |p, v| p.gate_sigmas = v,
            ),
            // At 0 every hypothesis would have lost lock before its first read.
            integer(
                "max_consecutive_outliers",
                Range::at_least(1.0),
                "reads",
                "a hypothesis that gates this many reads in a row has lost lock; when all have, the tracker starts over",
                |p| p.max_consecutive_outliers,
                |p, v| p.max_consecutive_outliers = v,
            ),
            float("reinit_gap_s", Range::POSITIVE, "s", "start over when a tag has not been read for this long", |p| p.reinit_gap_s, |p, v| p.reinit_gap_s = v),
            float(
                "reseed_interval_s",
                Range::NON_NEGATIVE,
                "s",
                "re-seeding: while the track is unresolved or its reported hypothesis gates reads, rerun the initial search this often on the last init_max_window_s of reads and add the candidates nobody follows at a small weight; 0 = off",
                |p| p.reseed_interval_s,
                |p, v| p.reseed_interval_s = v,
            ),
            float(
                "reseed_max_interval_s",
                Range::POSITIVE,
                "s",
                "longest interval between re-seeding searches while the track stays unresolved: each search started only because candidates still compete doubles the interval up to this; gated reads or a resolved track restart at reseed_interval_s",
                |p| p.reseed_max_interval_s,
                |p, v| p.reseed_max_interval_s = v,
            ),
            float(
                "max_speed_m_s",
                Range::POSITIVE,
                "m/s",
                "fastest the tag can move: after a restart, candidates beyond max_speed_m_s * gap + 3 sigma of the last estimate are dropped, and the last estimate is reported with the reachable ball in its sigma until the search commits",
                |p| p.max_speed_m_s,
                |p, v| p.max_speed_m_s = v,
            ),
            float(
                "region_margin_m",
                Range::NON_NEGATIVE,
                "m",
                "hypotheses further than this outside the scene's [region] are removed",
                |p| p.region_margin_m,
                |p, v| p.region_margin_m = v,
            ),
            float(
                "merge_distance_m",
                Range::NON_NEGATIVE,
                "m",
                "hypotheses closer than this are merged into one",
                |p| p.merge_distance_m,
                |p, v| p.merge_distance_m = v,
            ),
            integer(
                "max_hypotheses",
                Range::at_least(1.0),
                "hypotheses",
                "cap on live hypotheses (bounds the naive method's memory)",
                |p| p.max_hypotheses,
                |p, v| p.max_hypotheses = v,
            ),
            optional_float(
                "manoeuvre_q",
                Range::POSITIVE,
                "m^2/s^3",
                "process noise of a second, manoeuvring model run as an IMM beside q (fast inference); none: the paper's single model",
                |p| p.manoeuvre_q,
                |p, v| p.manoeuvre_q = v,
            ),
            // Above 0.5 the IMM would prefer switching to staying: no longer a regime model.
            float(
                "model_switch_probability",
                Range::closed(0.0, 0.5),
                "",
                "IMM Markov switch probability per read",
                |p| p.model_switch_probability,
                |p, v| p.model_switch_probability = v,
            ),
            integer(
                "read_budget",
                Range::at_least(1.0),
                "units",
                "most work one read does (1 unit ~ one hypothesis through one read, ~0.2 us): the initial search, replays and re-seeding carry the rest to the tag's next reads, which report nothing (or the re-acquisition estimate) until it is done (fast inference); for live input: offline runs (track, batch, st.track.run) are unbounded unless it is given",
                |p| p.read_budget,
                |p, v| p.read_budget = v,
            ),
            integer(
                "max_branching_hypotheses",
                Range::NON_NEGATIVE,
                "hypotheses",
                "ambiguity branching to the second-nearest candidate only while fewer hypotheses are live; 0: off",
                |p| p.max_branching_hypotheses,
                |p, v| p.max_branching_hypotheses = v,
            ),
            float(
                "perimeter_threshold_m",
                Range::POSITIVE,
                "m",
                "initial state pruning, 2D: a triangle of circle intersections with a larger perimeter (D_th) is dropped",
                |p| p.initial.perimeter_threshold_m,
                |p, v| p.initial.perimeter_threshold_m = v,
            ),
            float(
                "residual_threshold_m",
                Range::POSITIVE,
                "m",
                "initial state pruning keeps a position only if its range residual is below this at every antenna",
                |p| p.initial.residual_threshold_m,
                |p, v| p.initial.residual_threshold_m = v,
            ),
            float(
                "interpolation_sigma_m",
                Range::NON_NEGATIVE,
                "m",
                "extra 1-sigma range error from interpolating reads to a common time at initialisation (adds to R0, eq. 10)",
                |p| p.initial.interpolation_sigma_m,
                |p, v| p.initial.interpolation_sigma_m = v,
            ),
            integer(
                "init_max_hypotheses",
                Range::at_least(1.0),
                "hypotheses",
                "at most this many initial hypotheses (best likelihood first)",
                |p| p.initial.max_hypotheses,
                |p, v| p.initial.max_hypotheses = v,
            ),
            float(
                "init_max_speed_m_s",
                Range::NON_NEGATIVE,
                "m/s",
                "fastest plausible range rate: unwrapping two reads of an antenna also tries the branches one ambiguity step away",
                |p| p.initial.max_speed_m_s,
                |p, v| p.initial.max_speed_m_s = v,
            ),
            float(
                "init_max_pair_gap_s",
                Range::POSITIVE,
                "s",
                "an antenna whose two reads around the reference time are further apart is left out of initial state pruning",
                |p| p.initial.max_pair_gap_s,
                |p, v| p.initial.max_pair_gap_s = v,
            ),
        ],
    )
}
