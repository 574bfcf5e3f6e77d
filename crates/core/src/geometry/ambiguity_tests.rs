//! Tests of the scene geometry check (layouts from the GLAC paper and the
//! outside bench recordings).

use super::*;
use crate::scene::{Antenna, ChannelOffset, Region};
use std::f64::consts::PI;

fn scene(dimensions: usize, positions: &[[f64; 3]], region: Option<([f64; 3], [f64; 3])>, channels: &[f64]) -> Scene {
    let antennas = positions
        .iter()
        .enumerate()
        .map(|(i, p)| Antenna { id: i as i64 + 1, position: Vector3::from(*p), phase_offset_rad: 0.0, role: Default::default() })
        .collect();
    let region = region.map(|(lo, hi)| Region { min: Vector3::from(lo), max: Vector3::from(hi) });
    let channels = channels.iter().enumerate().map(|(i, &f)| ChannelOffset { frequency_hz: f, phase_offset_rad: 0.1 * i as f64 }).collect();
    Scene::new(dimensions, 0.0, 1.0, 2.0 * PI, 0.1, antennas, region, channels).unwrap()
}

const PAPER: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.8, 0.0], [0.8, 0.8, 0.0]];
const PAPER_REGION: ([f64; 3], [f64; 3]) = ([-0.5, -0.5, 0.05], [1.5, 1.5, 2.0]);
const BENCH: [[f64; 3]; 4] = [[0.0, 0.0, 0.15], [1.0, 0.05, 0.0], [0.05, 1.0, 0.4], [1.0, 1.0, 0.25]];
const BENCH_REGION: ([f64; 3], [f64; 3]) = ([-0.3, -0.3, 0.3], [1.3, 1.3, 1.6]);

fn quick() -> AmbiguityOptions {
    AmbiguityOptions { remedies: false, ..AmbiguityOptions::default() }
}

fn warnings(report: &AmbiguityReport) -> Vec<&TwinFamily> {
    report.families.iter().filter(|f| f.is_warning()).collect()
}

#[test]
fn paper_layout_has_the_line_family() {
    let s = scene(3, &PAPER, Some(PAPER_REGION), &[]);
    let report = analyse_scene(&s, &[], &AmbiguityOptions::default()).unwrap();
    let found = warnings(&report);
    assert_eq!(found.len(), 1, "{:?}", report.families);
    let family = found[0];
    assert_eq!(family.kind, FamilyKind::Line);
    assert_eq!(family.free, vec![3]);
    assert_eq!(family.line, vec![0, 1, 2]);
    assert!(family.exact && family.share > 0.5, "{family:?}");
    assert!(family.median_m > 0.2 && family.median_m < 0.5, "{family:?}");
    assert!(family.shifts.iter().all(|n| n[..3] == [0, 0, 0] && n[3] != 0));
    assert_eq!(family.remedy.move_antenna, Some(1));
    assert!(family.remedy.offset_m.is_some_and(|x| x > 0.0 && x <= 0.5));
    assert_eq!(family.remedy.hopping_breaks, Some(true));
    assert!(report.layout.iter().any(|f| f.kind == LayoutKind::Collinear && f.antennas == vec![0, 1, 2]));
    assert!(report.layout.iter().any(|f| f.kind == LayoutKind::Coplanar));
}

#[test]
fn bench_layout_has_no_warning() {
    let s = scene(3, &BENCH, Some(BENCH_REGION), &[]);
    let report = analyse_scene(&s, &[], &quick()).unwrap();
    assert!(warnings(&report).is_empty(), "{:?}", report.families);
    assert!(report.families.iter().all(|f| !f.exact));
    // Its four antennas lie within 1.3 mm of one tilted plane: a note only,
    // the region keeps (nearly all of) the mirror side out.
    assert!(report.layout.iter().all(|f| f.kind == LayoutKind::Coplanar), "{:?}", report.layout);
    assert!(report.inconclusive.is_none() && report.samples > 300);
}

#[test]
fn coplanar_without_region_has_the_mirror_family_and_a_region_excludes_it() {
    let square = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.2]];
    let tilted = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.7, 0.9, 0.0]];
    let open = scene(3, &tilted, None, &[]);
    let report = analyse_scene(&open, &[], &quick()).unwrap();
    let mirror: Vec<_> = report.families.iter().filter(|f| f.kind == FamilyKind::Mirror && f.exact).collect();
    assert_eq!(mirror.len(), 1, "{:?}", report.families);
    assert!(mirror[0].free.is_empty() && mirror[0].share > 0.5);
    let closed = scene(3, &tilted, Some(([-0.5, -0.5, 0.05], [1.5, 1.5, 1.5])), &[]);
    let report = analyse_scene(&closed, &[], &quick()).unwrap();
    assert!(report.families.iter().all(|f| f.kind != FamilyKind::Mirror), "{:?}", report.families);
    // Not coplanar: no mirror either, even without a region.
    let report = analyse_scene(&scene(3, &square, None, &[]), &[], &quick()).unwrap();
    assert!(report.families.iter().all(|f| !(f.kind == FamilyKind::Mirror && f.exact)), "{:?}", report.families);
}

#[test]
fn coincident_antennas_are_found() {
    let positions = [[0.0, 0.0, 0.0], [0.004, 0.0, 0.0], [1.0, 0.0, 0.3], [0.0, 1.0, 0.1], [1.0, 1.0, 0.5]];
    let findings = layout_findings(&scene(3, &positions, None, &[]), 0.01);
    let coincident: Vec<_> = findings.iter().filter(|f| f.kind == LayoutKind::Coincident).collect();
    assert_eq!(coincident.len(), 1);
    assert_eq!(coincident[0].antennas, vec![0, 1]);
    assert!((coincident[0].deviation_m - 0.004).abs() < 1e-12);
}

#[test]
fn hopping_with_calibrated_offsets_removes_the_line_family() {
    let channels = us_channels_hz();
    let s = scene(3, &PAPER, Some(PAPER_REGION), &channels);
    let frequencies = joint_frequencies(&s, &channels);
    assert_eq!(frequencies.len(), 50);
    let report = analyse_scene(&s, &frequencies, &quick()).unwrap();
    assert!(report.families.iter().all(|f| f.kind != FamilyKind::Line), "{:?}", report.families);
    // Uncalibrated channels are not relied on: one channel is analysed.
    let bare = scene(3, &PAPER, Some(PAPER_REGION), &[]);
    assert_eq!(joint_frequencies(&bare, &channels), vec![channels[0]]);
}

#[test]
fn twins_on_the_paper_layout_shift_ranges_by_whole_spacings() {
    let s = scene(3, &PAPER, Some(PAPER_REGION), &[]);
    let p = Vector3::new(0.45, 0.35, 0.7);
    let twins = twin_positions(&s, &p, &[], &AmbiguityOptions::default()).unwrap();
    assert!(!twins.is_empty());
    let spacing = s.candidate_spacing(DEFAULT_FREQUENCY_HZ);
    for twin in &twins {
        assert!((twin.position - p).norm() > 0.01);
        assert!(s.region.as_ref().unwrap().contains(&twin.position, 1e-9, 3));
        for (a, n) in s.antennas.iter().zip(&twin.shift) {
            let delta = (twin.position - a.position).norm() - (p - a.position).norm();
            assert!((delta - *n as f64 * spacing).abs() < 1e-3 * spacing, "{twin:?}");
        }
    }
    // The exact ones are the line family: antenna 4 (index 3) shifted alone.
    assert!(twins.iter().any(|t| t.shift == vec![0, 0, 0, 1] || t.shift == vec![0, 0, 0, -1]));
    // Restricted to the analysis' shifts, the cheap search finds them too.
    let report = analyse_scene(&s, &[], &quick()).unwrap();
    let shifts: Vec<Vec<i32>> = report.families.iter().filter(|f| f.exact).flat_map(|f| f.shifts.clone()).collect();
    let cheap = twin_search(&s, &[], &AmbiguityOptions::default()).unwrap().with_shifts(shifts).twins(&p);
    assert!(cheap.iter().any(|t| t.shift[3] != 0 && t.shift[..3] == [0, 0, 0]));
}

#[test]
fn planar_2d_paper_layout_fixes_the_position() {
    let s = scene(2, &PAPER, Some(([-0.5, -0.5, 0.0], [1.5, 1.5, 0.0])), &[]);
    let report = analyse_scene(&s, &[], &quick()).unwrap();
    assert!(warnings(&report).is_empty(), "{:?}", report.families);
}

#[test]
fn two_dimensional_line_of_antennas_has_the_mirror_family() {
    let positions = [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let s = scene(2, &positions, Some(([-1.0, -1.0, 0.0], [2.0, 1.0, 0.0])), &[]);
    let report = analyse_scene(&s, &[], &quick()).unwrap();
    assert!(report.families.iter().any(|f| f.kind == FamilyKind::Mirror && f.exact), "{:?}", report.families);
}

#[test]
fn bad_options_are_errors() {
    let s = scene(3, &PAPER, None, &[]);
    assert!(analyse_scene(&s, &[], &AmbiguityOptions { grid_points: 0, ..quick() }).is_err());
    assert!(analyse_scene(&s, &[-1.0], &quick()).is_err());
}

#[test]
fn shift_vectors_are_bounded_and_distinct() {
    let v = shift_vectors(4, 2);
    // The zero vector, 3⁴ − 1 vectors in {−1, 0, 1}, ±2 on each antenna and on all.
    assert_eq!(v.len(), 1 + 80 + 10);
    assert_eq!(v[0], vec![0; 4]);
    let mut sorted = v.clone();
    sorted.sort();
    sorted.dedup();
    assert_eq!(sorted.len(), v.len());
    assert!(shift_vectors(8, 2).len() < 200);
}

/// Cost figures for the report (`cargo test --release -- --ignored --nocapture timing`); no assertion on speed.
#[test]
#[ignore]
fn timing() {
    let s = scene(3, &PAPER, Some(PAPER_REGION), &[]);
    let t = std::time::Instant::now();
    let report = analyse_scene(&s, &[], &AmbiguityOptions::default()).unwrap();
    println!("analyse_scene with remedies: {:?}", t.elapsed());
    let shifts: Vec<Vec<i32>> = report.families.iter().filter(|f| f.exact).flat_map(|f| f.shifts.clone()).collect();
    let full = twin_search(&s, &[], &AmbiguityOptions::default()).unwrap();
    let cheap = full.clone().with_shifts(shifts);
    let points: Vec<Vector3<f64>> = (0..1000).map(|i| Vector3::new(0.1 + 0.0007 * i as f64, 0.2 + 0.0003 * i as f64, 0.4 + 0.0004 * i as f64)).collect();
    for (name, search) in [("restricted", &cheap), ("full", &full)] {
        let t = std::time::Instant::now();
        let n: usize = points.iter().map(|p| search.twins(p).len()).sum();
        println!("twins() {name} ({} shifts): {:.1} us per call, {n} twins", search.shifts().len(), t.elapsed().as_secs_f64() * 1e6 / points.len() as f64);
    }
}
