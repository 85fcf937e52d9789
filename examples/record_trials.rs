//! Record-error trials for the diagnosis (too slow for CI at these sizes): synthetic segments
//! whose inventory record is wrong in one of the ways of model §8 E8, generated from a small
//! dimension list typed here from the standards (ISO 4427, EN 1452, ISO 2531, ISO 13, EN 10224
//! and the class-20 asbestos-cement sizes of a utility's own inventory), independently of the
//! candidate table in `src/diagnose/catalogue.rs`, plus controls whose record is right.
//!
//! For every trial the diagnosis is given the record and the measurements only. A record error
//! is *detectable* when the fit with the true record lowers χ² below the recorded pipe's fit by
//! more than the test's threshold, the χ²₁ quantile at level α / (number of candidate records).
//! Reported: the share of detectable errors whose true record is in `record_set`, the median
//! size of the set, plastic pipes named `wall_thinning` (must be none), and controls answered
//! "none".
//!
//! Run: `cargo run --release --example record_trials -- N [BASE]`: N trials per kind of error
//! (and 2N controls), seeds from BASE (default 0).

use pipewave::diagnose::inventory::{
    candidates, InventoryPipe, InventoryProfile, RecordCandidate, RecordChange,
};
use pipewave::diagnose::stats::chi2_isf;
use pipewave::diagnose::{diagnose_segment, DiagnoseSettings, ALPHA};
use pipewave::invert::fit_segment;
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::synth::trial::trial;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::Arc;

use Material::*;

/// (material, DN, OD, walls of the standard's classes) typed from the standards' tables.
type Row = (Material, f64, f64, &'static [f64]);

/// PE (ISO 4427 SDR 11 / 17 / 26), PVC-U (EN 1452 SDR 17 / 21 / 26 / 33 / 41), ductile iron
/// (ISO 2531 K7 / K9 / K10), grey iron (ISO 13 A / B), steel (EN 10224 three walls), asbestos
/// cement (class 20 of the utility's inventory).
const SIZES: [Row; 28] = [
    (Mdpe, 90.0, 90.0, &[8.2, 5.4, 3.5]),
    (Mdpe, 125.0, 125.0, &[11.4, 7.4, 4.8]),
    (Mdpe, 180.0, 180.0, &[16.4, 10.7, 6.9]),
    (Mdpe, 250.0, 250.0, &[22.7, 14.8, 9.6]),
    (Hdpe, 110.0, 110.0, &[10.0, 6.6, 4.2]),
    (Hdpe, 160.0, 160.0, &[14.6, 9.5, 6.2]),
    (Hdpe, 225.0, 225.0, &[20.5, 13.4, 8.6]),
    (Hdpe, 315.0, 315.0, &[28.6, 18.7, 12.1]),
    (Pvc, 100.0, 110.0, &[6.6, 5.3, 4.2, 3.4, 2.7]),
    (Pvc, 150.0, 160.0, &[9.5, 7.7, 6.2, 4.9, 4.0]),
    (Pvc, 200.0, 200.0, &[11.9, 9.6, 7.7, 6.2, 4.9]),
    (Pvc, 250.0, 250.0, &[14.8, 11.9, 9.6, 7.7, 6.2]),
    (DuctileIron, 100.0, 118.0, &[5.0, 6.0]),
    (DuctileIron, 150.0, 170.0, &[5.0, 6.0, 6.5]),
    (DuctileIron, 200.0, 222.0, &[5.0, 6.3, 7.0]),
    (DuctileIron, 300.0, 326.0, &[5.6, 7.2, 8.0]),
    (CastIron, 100.0, 118.0, &[9.0, 9.9]),
    (CastIron, 150.0, 170.0, &[10.0, 11.0]),
    (CastIron, 200.0, 222.0, &[11.0, 12.1]),
    (CastIron, 300.0, 326.0, &[13.0, 14.3]),
    (Steel, 100.0, 114.3, &[3.6, 4.5, 5.6]),
    (Steel, 150.0, 168.3, &[4.5, 5.6, 7.1]),
    (Steel, 200.0, 219.1, &[5.0, 6.3, 8.0]),
    (Steel, 300.0, 323.9, &[5.6, 7.1, 8.8]),
    (AsbestosCement, 100.0, 122.0, &[11.5]),
    (AsbestosCement, 150.0, 177.0, &[14.0]),
    (AsbestosCement, 200.0, 232.0, &[17.0]),
    (AsbestosCement, 300.0, 340.0, &[20.0]),
];

/// The kinds of record error tried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Control,
    WallClass,
    WrongMaterial,
    DnForOd,
    Inches,
}

/// A utility's inventory: shares of a network with old iron and newer plastics, each material
/// laid in its era, sizes from the list above.
fn profile() -> InventoryProfile {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let mix = [
        (CastIron, 0.25, 1900, 1965),
        (DuctileIron, 0.2, 1965, 2020),
        (Steel, 0.07, 1920, 2010),
        (Pvc, 0.16, 1965, 2005),
        (Mdpe, 0.14, 1980, 2020),
        (Hdpe, 0.1, 1990, 2020),
        (AsbestosCement, 0.08, 1935, 1985),
    ];
    let mut pipes = Vec::new();
    for _ in 0..600 {
        let mut u = rng.gen::<f64>();
        let &(m, _, y0, y1) = mix
            .iter()
            .find(|x| {
                u -= x.1;
                u < 0.0
            })
            .unwrap_or(&mix[0]);
        let rows: Vec<&Row> = SIZES.iter().filter(|r| r.0 == m).collect();
        let r = rows[rng.gen_range(0..rows.len())];
        // The commonest class of each material: SDR 11 PE, SDR 21 PVC, K9, class A, the
        // middle steel wall.
        let idx = match m {
            Mdpe | Hdpe | CastIron | AsbestosCement => 0,
            _ => 1,
        };
        pipes.push(InventoryPipe {
            material: m,
            od_mm: r.2,
            wall_mm: r.3[idx.min(r.3.len() - 1)],
            install_year: Some(rng.gen_range(y0..=y1)),
        });
    }
    InventoryProfile { pipes }
}

/// A pipe: material, OD and wall (mm).
type PipeRecord = (Material, f64, f64);

/// A random (true pipe, record) of `kind`.
fn draw<R: Rng>(rng: &mut R, kind: Kind) -> Option<(PipeRecord, PipeRecord)> {
    let r = SIZES[rng.gen_range(0..SIZES.len())];
    let w = r.3[rng.gen_range(0..r.3.len())];
    let truth = (r.0, r.2, w);
    let record = match kind {
        Kind::Control => truth,
        Kind::WallClass => {
            let others: Vec<f64> = r.3.iter().copied().filter(|x| *x != w).collect();
            if others.is_empty() {
                return None;
            }
            (r.0, r.2, others[rng.gen_range(0..others.len())])
        }
        Kind::WrongMaterial => {
            // Recorded as another material of the same nominal size, its commonest wall.
            let same_dn: Vec<&Row> = SIZES
                .iter()
                .filter(|x| x.0 != r.0 && (x.1 - r.1).abs() < 1.0)
                .collect();
            if same_dn.is_empty() {
                return None;
            }
            let o = same_dn[rng.gen_range(0..same_dn.len())];
            (o.0, o.2, o.3[o.3.len() / 2])
        }
        Kind::DnForOd => {
            if r.1 >= r.2 - 0.5 {
                return None;
            }
            (r.0, r.1, w)
        }
        Kind::Inches => {
            if r.2 < 300.0 {
                return None;
            }
            (r.0, r.2 / 25.4, w / 25.4)
        }
    };
    Some((truth, record))
}

struct Outcome {
    kind: Kind,
    truth: PipeRecord,
    record: PipeRecord,
    detectable: bool,
    structured: bool,
    named: Option<Effect>,
    set: Vec<(RecordCandidate, f64)>,
    in_set: bool,
    chi2: (f64, f64),
}

fn run_trial(kind: Kind, seed: u64, profile: &Arc<InventoryProfile>) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (t, truth, record) = loop {
        let Some((truth, record)) = draw(&mut rng, kind) else {
            continue;
        };
        if let Some(t) = trial(&mut rng, truth.0, (truth.1, truth.2), None, record) {
            break (t, truth, record);
        }
    };
    let settings = DiagnoseSettings {
        inventory: Some(profile.clone()),
        ..DiagnoseSettings::default()
    };
    let d = diagnose_segment(&t.data, None, &settings);
    let true_rec = RecordCandidate {
        change: RecordChange::Material,
        material: truth.0,
        outside_diameter_mm: truth.1,
        wall_mm: truth.2,
    };
    let n = candidates(&t.data, Some(profile)).len().max(1);
    let chi2_base = d.before.chi2();
    let chi2_true = true_rec
        .segment_data(&d.data)
        .map(|td| fit_segment(&td, &Default::default(), settings.seed).misfit)
        .unwrap_or(f64::INFINITY);
    let detectable =
        kind != Kind::Control && chi2_base - chi2_true > chi2_isf(ALPHA / n as f64, 1.0);
    let reported = d.named == Some(Effect::InventoryError)
        || d.ambiguous_with.contains(&Effect::InventoryError);
    let best = d
        .record_set
        .iter()
        .map(|m| m.chi2)
        .fold(f64::INFINITY, f64::min);
    let set: Vec<(RecordCandidate, f64)> = if reported {
        d.record_set
            .iter()
            .map(|m| (m.candidate, m.chi2 - best))
            .collect()
    } else {
        Vec::new()
    };
    let in_set = set.iter().any(|(c, _)| {
        c.material == truth.0
            && (c.outside_diameter_mm - truth.1).abs() <= 0.6
            && (c.wall_mm - truth.2).abs() <= 0.06
    });
    Outcome {
        kind,
        truth,
        record,
        detectable,
        structured: d.structure.structured,
        named: d.named,
        set,
        in_set,
        chi2: (chi2_base, chi2_true),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10);
    let base: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(0);
    let profile = Arc::new(profile());
    let mut cases: Vec<(Kind, u64)> = Vec::new();
    for (k, kind) in [
        Kind::WallClass,
        Kind::WrongMaterial,
        Kind::DnForOd,
        Kind::Inches,
    ]
    .into_iter()
    .enumerate()
    {
        for i in 0..n {
            cases.push((kind, base + (k * 10_000 + i) as u64));
        }
    }
    for i in 0..2 * n {
        cases.push((Kind::Control, base + (90_000 + i) as u64));
    }
    let t0 = std::time::Instant::now();
    let out: Vec<Outcome> = cases
        .par_iter()
        .map(|&(kind, seed)| run_trial(kind, seed, &profile))
        .collect();
    let name = |m: Material, od: f64, w: f64| format!("{} {od:.1}/{w:.2}", m.code());
    for o in &out {
        println!(
            "{:?}: truth {} recorded {}; chi2 base {:.1}, true record {:.1}; detectable {}; structured {}; named {}; in set {}; set [{}]",
            o.kind,
            name(o.truth.0, o.truth.1, o.truth.2),
            name(o.record.0, o.record.1, o.record.2),
            o.chi2.0,
            o.chi2.1,
            o.detectable,
            o.structured,
            o.named.map(|e| e.name()).unwrap_or("none"),
            o.in_set,
            o.set
                .iter()
                .map(|(c, d)| format!("{} (+{d:.1})", c.label()))
                .collect::<Vec<_>>()
                .join(" | ")
        );
    }
    println!();
    let errs: Vec<&Outcome> = out.iter().filter(|o| o.kind != Kind::Control).collect();
    for kind in [
        Kind::WallClass,
        Kind::WrongMaterial,
        Kind::DnForOd,
        Kind::Inches,
    ] {
        let k: Vec<&&Outcome> = errs.iter().filter(|o| o.kind == kind).collect();
        let det: Vec<&&&Outcome> = k.iter().filter(|o| o.detectable).collect();
        let hit = det.iter().filter(|o| o.in_set).count();
        println!(
            "{kind:?}: {} trials, {} detectable, true record in record_set {hit}/{}",
            k.len(),
            det.len(),
            det.len()
        );
    }
    let det: Vec<&&Outcome> = errs.iter().filter(|o| o.detectable).collect();
    let hit = det.iter().filter(|o| o.in_set).count();
    let mut sizes: Vec<usize> = det
        .iter()
        .filter(|o| !o.set.is_empty())
        .map(|o| o.set.len())
        .collect();
    sizes.sort();
    let median = if sizes.is_empty() {
        f64::NAN
    } else if sizes.len() % 2 == 1 {
        sizes[sizes.len() / 2] as f64
    } else {
        (sizes[sizes.len() / 2 - 1] + sizes[sizes.len() / 2]) as f64 / 2.0
    };
    let plastic_thinning = out
        .iter()
        .filter(|o| o.record.0.is_plastic() || o.truth.0.is_plastic())
        .filter(|o| o.named == Some(Effect::WallThinning))
        .count();
    let controls: Vec<&Outcome> = out.iter().filter(|o| o.kind == Kind::Control).collect();
    let none = controls.iter().filter(|o| o.named.is_none()).count();
    println!(
        "record errors: {} trials, {} detectable; true record in record_set for {hit}/{} ({:.1} %); median set size {median} (sizes {:?})",
        errs.len(),
        det.len(),
        det.len(),
        100.0 * hit as f64 / det.len().max(1) as f64,
        sizes
    );
    println!(
        "plastic pipes named wall_thinning: {plastic_thinning} of {}",
        out.iter()
            .filter(|o| o.record.0.is_plastic() || o.truth.0.is_plastic())
            .count()
    );
    println!(
        "controls: none for {none}/{} ({:.1} %)",
        controls.len(),
        100.0 * none as f64 / controls.len().max(1) as f64
    );
    println!(
        "{} trials in {:.0} s on {} threads",
        out.len(),
        t0.elapsed().as_secs_f64(),
        rayon::current_num_threads()
    );
}
