//! The one list of tracking methods: name, pipeline, input, which
//! parameter table it reads, the constructor that builds its tracker, and
//! a one-line description. [`super::make`] looks a method up here and
//! calls its constructor; the bindings, `scattertrack.track`, the CLI's
//! `methods` command and `docs/parameters.md` all read [`METHODS`].
//!
//! Registering a method: one entry here. A core method's entry names its
//! constructor ([`Build`]: a `build` function in the method's own file, or
//! a named variant in [`super::variants`]) and reuses a parameter table
//! where it needs no new parameter; a new tracker file may be declared
//! right here (`#[path = "….rs"] mod …;`) so that `mod.rs` needs no edit.
//! A Python method (no constructor) needs its runner in
//! `python/scattertrack/track/`.
//!
//! Marvel's estimator (a GTSAM factor graph) and its parameter table are
//! in Python (`scattertrack.fusion.params`): the table sits next to the
//! dataclass the estimator reads, and Python passes it to the core's
//! checker ([`crate::params::Schemas::from_rows`]) so its values are
//! parsed and checked exactly like the core's.

use super::glac_params::glac_table;
use super::turbotrack_params::turbotrack_table;
use super::{ellipse_intersection, glac, rfind, turbotrack, variants, Params, Tracker};
use crate::error::{Error, Result};
use crate::params::{Schemas, Value};
use crate::scene::Scene;

#[path = "trilateration_ekf.rs"] mod trilateration_ekf;

/// The hardware a method's input comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pipeline {
    /// A COTS RFID reader (phase reads).
    Cots,
    /// A reader plus an SDR localization helper (wideband frames).
    Helper,
    /// A drone carrying LoRa-backscatter tags and an IMU.
    Drone,
}

impl Pipeline {
    pub fn as_str(self) -> &'static str {
        match self {
            Pipeline::Cots => "cots",
            Pipeline::Helper => "helper",
            Pipeline::Drone => "drone",
        }
    }
}

/// What a method consumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// Phase reads (reads.csv).
    Reads,
    /// Wideband frames (frames.csv, or a helper's SigMF recording turned into frames).
    Frames,
    /// IMU samples and pose features (features.csv, or a LoRa SigMF recording).
    FeaturesImu,
    /// IMU samples and a LoRa SigMF recording (its own pose sensing).
    RecordingImu,
}

impl Input {
    /// A short key: `reads`, `frames`, `features+imu`, `sigmf+imu`.
    pub fn as_str(self) -> &'static str {
        match self {
            Input::Reads => "reads",
            Input::Frames => "frames",
            Input::FeaturesImu => "features+imu",
            Input::RecordingImu => "sigmf+imu",
        }
    }

    /// The files, for listings.
    pub fn describe(self) -> &'static str {
        match self {
            Input::Reads => "reads.csv",
            Input::Frames => "frames.csv or a helper SigMF recording",
            Input::FeaturesImu => "imu.csv + features.csv or a LoRa SigMF recording",
            Input::RecordingImu => "imu.csv + a LoRa SigMF recording",
        }
    }
}

/// Which table a method's parameters are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parameters {
    /// `GlacParams` ([`glac_table`]).
    Glac,
    /// `TurboTrackParams` ([`turbotrack_table`]).
    TurboTrack,
    /// A table kept in Python with the estimator (Marvel).
    Python,
}

/// A core method's constructor: its tracker over `scene` from the
/// parameter block its table fills (the variants set what defines them on
/// top). Fails on a scene or parameters the tracker rejects.
pub type Build = fn(&Scene, &Params) -> Result<Box<dyn Tracker>>;

/// One registered method.
#[derive(Debug, Clone, Copy)]
pub struct Method {
    pub name: &'static str,
    pub pipeline: Pipeline,
    pub input: Input,
    pub parameters: Parameters,
    /// Builds the tracker ([`super::make`]); `None` for a method whose
    /// estimator is in Python.
    pub build: Option<Build>,
    /// One line: what the method does and where it comes from.
    pub description: &'static str,
}

impl Method {
    /// Whether the Rust core runs the estimator ([`super::make`] builds it).
    pub fn in_core(&self) -> bool {
        self.build.is_some()
    }
}

/// A COTS-reader method over phase reads with the GLAC table.
const fn cots(name: &'static str, build: Build, description: &'static str) -> Method {
    Method { name, pipeline: Pipeline::Cots, input: Input::Reads, parameters: Parameters::Glac, build: Some(build), description }
}

/// A localization-helper method over wideband frames with the TurboTrack table.
const fn helper(name: &'static str, build: Build, description: &'static str) -> Method {
    Method {
        name,
        pipeline: Pipeline::Helper,
        input: Input::Frames,
        parameters: Parameters::TurboTrack,
        build: Some(build),
        description,
    }
}

/// Every method, in the order listings show them.
pub const METHODS: &[Method] = &[
    cots("glac", glac::build, "GLAC: HMM over candidate trajectories, one EKF each, nearest-neighbour pruning and initial state pruning (the paper's tracker)"),
    cots("glac-no-velocity", variants::glac_no_velocity, "GLAC with a position random walk instead of the constant-velocity model (paper sec. 5.2.2, scheme 2)"),
    cots("glac-sync", variants::glac_sync, "GLAC treating each group of reads covering every antenna as one trilaterated measurement (sec. 5.2.2, scheme 3)"),
    cots("glac-sync-no-velocity", variants::glac_sync_no_velocity, "glac-sync with a position random walk (sec. 5.2.2)"),
    cots(
        "glac-naive",
        variants::glac_naive,
        "GLAC without nearest-neighbour pruning or quick stop: every hypothesis branches on every candidate distance, capped by max_hypotheses (sec. 5.2.3)",
    ),
    cots("trilateration-ekf", trilateration_ekf::build, "baseline: one EKF on [p, v] fed ranges unwrapped from each antenna and channel's phase, from a multilateration fix whose twins the first reads rule out"),
    helper("turbotrack", turbotrack::build, "TurboTrack: particle filter over a mixture of each receiver's candidate path lengths, near-optimal proposal (thesis ch. 5)"),
    helper("gaussian-pf", variants::gaussian_pf, "TurboTrack baseline: one broad Gaussian around the strongest candidate, bootstrap proposal (thesis sec. 7.2(a))"),
    helper("uniform-pf", variants::uniform_pf, "TurboTrack baseline: particles spread uniformly over the [region], bootstrap proposal (thesis sec. 7.2(b))"),
    helper("ellipse-intersection", ellipse_intersection::build, "per frame, the intersection of the strongest candidates' ellipsoids, no filtering (thesis sec. 7.2(a))"),
    helper("rfind", rfind::build, "RFind-style: a static tag localised from frames pooled over rfind_window_s (thesis Table 7.1)"),
    Method {
        name: "marvel",
        pipeline: Pipeline::Drone,
        input: Input::FeaturesImu,
        parameters: Parameters::Python,
        build: None,
        description: "Marvel: LoRa-backscatter range/angle/heading fused with the IMU in a sliding-window factor graph (GTSAM), controller position estimated (paper sec. IV)",
    },
    Method {
        name: "ulocate",
        pipeline: Pipeline::Drone,
        input: Input::RecordingImu,
        parameters: Parameters::Python,
        build: None,
        description: "mu-locate-style Doppler-blind pose sensing of a LoRa recording, fused like marvel: the paper's Fig. 9 baseline",
    },
];

/// The registered method `name`; an error naming the known ones otherwise.
pub fn method(name: &str) -> Result<&'static Method> {
    METHODS.iter().find(|m| m.name == name).ok_or_else(|| Error::UnknownMethod(name.to_string(), names().join(", ")))
}

/// Every registered name, in listing order.
pub fn names() -> Vec<&'static str> {
    METHODS.iter().map(|m| m.name).collect()
}

/// The parameter table of a core method, with its defaults.
pub fn schemas(name: &str) -> Result<Schemas> {
    Ok(match method(name)?.parameters {
        Parameters::Glac => glac_table().labelled(name).schemas(),
        Parameters::TurboTrack => turbotrack_table().labelled(name).schemas(),
        Parameters::Python => return Err(Error::NotInCore(name.to_string())),
    })
}

/// The parameters of core method `name`: its table's defaults with
/// `values` (name → value) set, each checked by its row. [`super::make`]
/// applies the variant on top.
pub fn params(name: &str, values: &[(String, Value)]) -> Result<Params> {
    Ok(match method(name)?.parameters {
        Parameters::Glac => glac_table().labelled(name).build(values)?.into(),
        Parameters::TurboTrack => turbotrack_table().labelled(name).build(values)?.into(),
        Parameters::Python => return Err(Error::NotInCore(name.to_string())),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{Kind, Schema};
    use crate::scene::{Antenna, Region, Role};
    use nalgebra::Vector3;
    use crate::track::{GlacParams, TurboTrackParams};

    fn core_tables() -> Vec<Schemas> {
        vec![glac_table().schemas(), turbotrack_table().schemas()]
    }

    /// A value inside `schema`'s range other than its default where one exists.
    fn another_value(schema: &Schema) -> Value {
        match (&schema.kind, &schema.default) {
            (Kind::Bool, Value::Bool(b)) => Value::Bool(!b),
            (Kind::Choice(c), _) => Value::Text(c.last().unwrap().clone()),
            (Kind::Integer, Value::Integer(i)) if schema.range.contains((*i + 1) as f64) => Value::Integer(*i + 1),
            (Kind::Float, Value::Float(x)) if schema.range.contains(x * 0.5) && *x != 0.0 => Value::Float(x * 0.5),
            (Kind::Float, Value::None) => Value::Float(0.5),
            _ => schema.default.clone(),
        }
    }

    #[test]
    fn names_are_unique_and_every_core_method_builds_its_parameters() {
        let all = names();
        for (i, n) in all.iter().enumerate() {
            assert!(!all[..i].contains(n), "{n} registered twice");
        }
        for m in METHODS.iter().filter(|m| m.in_core()) {
            assert_eq!(params(m.name, &[]).unwrap(), Params::default(), "{}", m.name);
            assert_eq!(schemas(m.name).unwrap().label, m.name);
        }
    }

    /// A 3D scene of four antennas; a helper's when `roles` is given.
    fn scene(roles: Option<[Role; 4]>) -> Scene {
        let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.2], [0.0, 1.0, 0.4], [1.0, 1.0, 1.0]];
        let antennas = (0..4)
            .map(|i| Antenna {
                id: i as i64 + 1,
                position: Vector3::from(positions[i]),
                phase_offset_rad: 0.0,
                role: roles.map_or(Role::TxRx, |r| r[i]),
            })
            .collect();
        let region = Region { min: Vector3::new(0.1, 0.1, 0.1), max: Vector3::new(0.9, 0.9, 0.9) };
        Scene::new(3, 0.0, 1.0, std::f64::consts::TAU, 0.1, antennas, Some(region), Vec::new()).unwrap()
    }

    #[test]
    fn every_core_method_is_built_by_its_registry_constructor() {
        let cots = scene(None);
        let helper = scene(Some([Role::Tx, Role::Rx, Role::Rx, Role::Rx]));
        for m in METHODS.iter().filter(|m| m.in_core()) {
            let s = if m.pipeline == Pipeline::Helper { &helper } else { &cots };
            let params = params(m.name, &[]).unwrap();
            let mut tracker = super::super::make(m.name, s, &params).unwrap_or_else(|e| panic!("{}: {e}", m.name));
            assert_eq!(tracker.stats().measurements, 0, "{}", m.name);
            tracker.reset();
        }
        assert_eq!(super::super::make("marvel", &cots, &Params::default()).err(), Some(Error::NotInCore("marvel".into())));
        assert!(matches!(super::super::make("nope", &cots, &Params::default()), Err(Error::UnknownMethod(..))));
    }

    #[test]
    fn unknown_methods_name_the_known_ones() {
        let message = schemas("nope").unwrap_err().to_string();
        assert!(message.contains("unknown method 'nope'") && message.contains("glac") && message.contains("marvel"), "{message}");
        assert_eq!(params("marvel", &[]).unwrap_err(), Error::NotInCore("marvel".into()));
    }

    #[test]
    fn every_default_is_within_its_own_range() {
        for table in core_tables() {
            for row in &table.rows {
                assert_eq!(row.convert(&row.default).as_ref(), Ok(&row.default), "{}: default {}", row.name, row.default);
                assert!(!row.description.is_empty() && !row.description.contains('\n'), "{}", row.name);
            }
            assert!(Schemas::from_rows(&table.label, table.rows.clone()).is_ok());
        }
    }

    #[test]
    fn every_name_can_be_set_and_read_back() {
        for (label, table) in [("glac", glac_table().schemas()), ("turbotrack", turbotrack_table().schemas())] {
            for row in &table.rows {
                let value = another_value(row);
                let built = params(label, &[(row.name.clone(), value.clone())]).unwrap_or_else(|e| panic!("{}: {e}", row.name));
                let read = if label == "glac" {
                    glac_table().get(&built.glac, &row.name)
                } else {
                    turbotrack_table().get(&built.turbotrack, &row.name)
                };
                assert_eq!(read.unwrap(), value, "{}", row.name);
                // And from text, as the command line gives it.
                let text = match &value {
                    Value::Text(s) => s.clone(),
                    other => other.to_string(),
                };
                assert_eq!(row.parse(&text).unwrap(), value, "{} from {text:?}", row.name);
            }
        }
    }

    #[test]
    fn the_tables_hold_the_structs_defaults() {
        let glac = glac_table().schemas();
        let d = |n: &str| glac.find(n).unwrap().default.clone();
        let g = GlacParams::default();
        assert_eq!(d("max_hypotheses"), Value::Integer(g.max_hypotheses as i64));
        assert_eq!(d("q"), Value::Float(0.02));
        assert_eq!(d("motion"), Value::Text("constant-velocity".into()));
        assert_eq!(d("phase_noise_rad"), Value::None);
        assert_eq!(d("manoeuvre_q"), Value::Float(1.0));
        let turbo = turbotrack_table().schemas();
        assert_eq!(turbo.find("particles").unwrap().default, Value::Integer(TurboTrackParams::default().particles as i64));
        assert_eq!(turbo.find("candidate_weighting").unwrap().default, Value::Text("likelihood".into()));
    }

    #[test]
    fn ranges_are_enforced_with_the_parameter_named() {
        let cases: &[(&str, &str, &str)] = &[
            ("max_hypotheses", "-1", ">= 1"),
            ("max_hypotheses", "0", ">= 1"),
            ("model_switch_probability", "0.7", "[0, 0.5]"),
            ("quick_stop", "1", "[0, 1)"),
            ("q", "abc", "a float > 0"),
            ("q", "nan", "a float > 0"),
            ("gate_sigmas", "inf", "a float > 0"),
            ("max_branching_hypotheses", "-3", ">= 0"),
            ("motion", "zigzag", "one of constant-velocity, random-walk"),
        ];
        for (name, text, fragment) in cases {
            let mut p = GlacParams::default();
            match glac_table().set_text(&mut p, name, text) {
                Err(Error::Parameter { name: n, reason }) => {
                    assert_eq!(&n, name);
                    assert!(reason.contains(fragment) && reason.to_lowercase().contains(text), "{name}={text}: {reason}");
                }
                other => panic!("{name}={text}: {other:?}"),
            }
        }
        let mut p = TurboTrackParams::default();
        assert!(turbotrack_table().set_text(&mut p, "resample_threshold", "1.5").is_err());
        assert!(turbotrack_table().set_text(&mut p, "seed", "-1").is_err());
    }

    #[test]
    fn motion_and_q_commute() {
        let a = params("glac", &[("motion".into(), Value::Text("random-walk".into())), ("q".into(), Value::Float(0.3))]).unwrap();
        let b = params("glac", &[("q".into(), Value::Float(0.3)), ("motion".into(), Value::Text("random-walk".into()))]).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.glac.motion, crate::model::MotionModel::RandomWalk { q: 0.3 });
    }
}
