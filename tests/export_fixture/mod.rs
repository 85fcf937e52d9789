//! Synthetic networks for the export and audit tests and the size/time example: segments with
//! geometry around Southampton (EPSG:27700), measurements, and fits with curves on the standard
//! grid, written through the database API (`import`, `start_run`, `insert_fit_with_curves`). No
//! real fitting: the fitted values are made up, deterministic functions of the segment number.
#![allow(dead_code)]

use std::path::Path;

use pipewave::db::{
    self, finish_run, insert_fit_with_curves, start_run, CurvePoint, Database, FitRow, FitStatus,
    ImportOptions, ImportSource, NewRun, RunCounts, RunStatus,
};
use pipewave::physics::curves::STANDARD_GRID_HZ;
use pipewave::physics::{ContactMode, Model};

/// Southampton, on the British National Grid (EPSG:27700), m.
pub const ORIGIN_EN: (f64, f64) = (441_800.0, 111_900.0);

/// How segment `i` of a fixture network is made (so tests can predict it).
pub fn has_geometry(i: usize) -> bool {
    i % 10 != 7
}
pub fn is_unfitted(i: usize) -> bool {
    i % 20 == 3
}
pub fn is_failed(i: usize) -> bool {
    i % 25 == 5
}
pub fn is_flagged(i: usize) -> bool {
    i % 6 == 1
}
pub fn segment_id(i: usize) -> String {
    format!("S{i:05}")
}

/// A small deterministic generator (SplitMix64), so fixtures need no extra dependency.
pub struct Mix(u64);
impl Mix {
    pub fn new(seed: u64) -> Mix {
        Mix(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[(self.next_u64() % v.len() as u64) as usize]
    }
}

const SOILS: [&str; 6] = [
    "clay",
    "sandy clay",
    "silt",
    "sand",
    "gravel",
    "made ground",
];

/// (material, diameters mm, wall mm, base speed m/s)
const MATERIALS: [(&str, &[f64], f64, f64); 4] = [
    ("CI", &[100.0, 150.0, 200.0, 300.0], 9.0, 1150.0),
    ("DI", &[110.0, 160.0, 250.0], 6.0, 1250.0),
    ("PVC", &[110.0, 160.0, 225.0], 8.0, 480.0),
    ("MDPE", &[90.0, 125.0, 180.0], 10.0, 330.0),
];

/// The leak-band-ish speed law of segment `i`: c(f) = c0 + slope·f, m/s.
pub fn speed_law(i: usize, base: f64) -> (f64, f64) {
    let c0 = base * (0.9 + 0.2 * ((i * 37) % 101) as f64 / 100.0);
    (c0, 0.02 + 0.01 * (i % 3) as f64)
}

/// The compressional speed of soil type `soil`, m/s (made up, per type), for segment `i`.
pub fn soil_p_speed(i: usize, soil: &str) -> f64 {
    let base = match soil {
        "clay" => 220.0,
        "sandy clay" => 260.0,
        "silt" => 240.0,
        "sand" => 320.0,
        "gravel" => 400.0,
        _ => 280.0,
    };
    base * (0.95 + 0.1 * ((i * 13) % 10) as f64 / 10.0)
}

/// The relative one-sigma error of segment `i`'s c_P: determined (2-6 %) except every 8th.
pub fn soil_p_rel_std(i: usize) -> f64 {
    if i % 8 == 0 {
        0.25
    } else {
        0.02 + 0.01 * (i % 5) as f64
    }
}

/// The relative one-sigma error of segment `i`'s leak-band speed (None: not stored, as an
/// older fit): 0.2-2.7 %.
pub fn leak_band_rel_std(i: usize) -> Option<f64> {
    (i % 17 != 4).then(|| 0.002 + 0.0025 * ((i * 7) % 11) as f64)
}

/// Plastic materials of the fixture (their fits determine c_S as well).
pub fn is_plastic(material: &str) -> bool {
    matches!(material, "PVC" | "MDPE")
}

/// Create (or extend) the database at `path` with `n` segments, their measurements, and one
/// calibrate run with fits for all but the unfitted ones.
pub fn build(path: &Path, n: usize) -> Database {
    let mut database = Database::open(path).expect("open fixture db");
    // Fixture speed: no fsync per fit (20,000 transactions otherwise).
    database
        .conn()
        .pragma_update(None, "synchronous", "OFF")
        .expect("pragma");
    let mut rng = Mix::new(20_240_501);
    let mut seg = csv::Writer::from_writer(Vec::new());
    seg.write_record([
        "segment_id",
        "material",
        "outer_diameter_mm",
        "wall_thickness_mm",
        "soil_density_kg_m3",
        "length_m",
        "soil_type",
        "install_year",
        "geometry_wkt",
        "srid",
    ])
    .unwrap();
    let mut meas = csv::Writer::from_writer(Vec::new());
    meas.write_record([
        "segment_id",
        "frequency_hz",
        "k_re_rad_per_m",
        "attenuation_np_per_m",
        "k_re_std",
        "attenuation_std",
    ])
    .unwrap();
    // Spread the network over a square whose side grows with sqrt(n): ~150 m per segment.
    let side = 150.0 * (n as f64).sqrt().max(4.0);
    let mut specs = Vec::with_capacity(n);
    let mut soils = Vec::with_capacity(n);
    for i in 0..n {
        let (material, diameters, wall, base) = *rng.pick(&MATERIALS);
        let d = *rng.pick(diameters);
        let soil = *rng.pick(&SOILS);
        let x0 = ORIGIN_EN.0 + (rng.unit() - 0.5) * side;
        let y0 = ORIGIN_EN.1 + (rng.unit() - 0.5) * side;
        let ang = rng.unit() * std::f64::consts::TAU;
        let len = 60.0 + 90.0 * rng.unit();
        let (x1, y1) = (x0 + 0.5 * len * ang.cos(), y0 + 0.5 * len * ang.sin());
        let (x2, y2) = (
            x1 + 0.5 * len * (ang + 0.3).cos(),
            y1 + 0.5 * len * (ang + 0.3).sin(),
        );
        let (wkt, srid) = if has_geometry(i) {
            (
                format!("LINESTRING ({x0:.3} {y0:.3}, {x1:.3} {y1:.3}, {x2:.3} {y2:.3})"),
                "27700".to_string(),
            )
        } else {
            (String::new(), String::new())
        };
        seg.write_record([
            segment_id(i),
            material.to_string(),
            d.to_string(),
            wall.to_string(),
            "1900".to_string(),
            format!("{len:.1}"),
            soil.to_string(),
            (1930 + i % 90).to_string(),
            wkt,
            srid,
        ])
        .unwrap();
        let (c0, slope) = speed_law(i, base);
        for f in [100.0, 200.0, 400.0, 600.0, 800.0] {
            let noise = 1.0 + 0.03 * (rng.unit() - 0.5) * if i % 13 == 0 { 8.0 } else { 1.0 };
            let c = (c0 + slope * f) * noise;
            let k = std::f64::consts::TAU * f / c;
            let att_db = 0.002 * f.sqrt() * (1.0 + 0.1 * (rng.unit() - 0.5));
            meas.write_record([
                segment_id(i),
                f.to_string(),
                k.to_string(),
                (att_db / pipewave::units::DB_PER_NP).to_string(),
                (0.01 * k).to_string(),
                "0.001".to_string(),
            ])
            .unwrap();
        }
        specs.push((material, base, d));
        soils.push(soil);
    }
    let report = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes(
            "segments.csv",
            seg.into_inner().unwrap(),
        )),
        Some(&ImportSource::from_bytes(
            "measurements.csv",
            meas.into_inner().unwrap(),
        )),
        ImportOptions::default(),
    )
    .expect("import fixture");
    assert!(report.errors.is_empty(), "{:?}", &report.errors[..1]);

    let run = NewRun {
        seed: 42,
        model: Model::Full,
        contact_mode: ContactMode::Reciprocal,
        method: "default".into(),
        effects: String::new(),
        program_version: env!("CARGO_PKG_VERSION").into(),
        jobs: Some(2),
        n_segments: n as i64,
    };
    let run_id = start_run(database.conn(), &run).expect("start run");
    let mut counts = RunCounts::default();
    for (i, (_material, base, _d)) in specs.iter().enumerate() {
        if is_unfitted(i) {
            continue;
        }
        let id = segment_id(i);
        let status = if is_failed(i) {
            FitStatus::Failed
        } else if is_flagged(i) {
            FitStatus::Flagged
        } else {
            FitStatus::Ok
        };
        let mut fit = FitRow::new(&id, run_id, status, Model::Full, ContactMode::Reciprocal);
        let curve: Vec<CurvePoint> = if status == FitStatus::Failed {
            fit.message = Some("no root of the dispersion relation near 300 Hz".into());
            counts.n_failed += 1;
            Vec::new()
        } else {
            fit.soil_youngs_modulus_pa =
                Some(2e7 * (1.0 + 9.0 * ((i * 7919) % 1000) as f64 / 1000.0));
            fit.soil_youngs_modulus_std_pa = Some(1e6 + i as f64);
            fit.soil_poisson = Some(0.25 + 0.2 * ((i * 31) % 100) as f64 / 100.0);
            fit.soil_poisson_std = if i % 4 == 0 { None } else { Some(0.01) };
            fit.contact = Some(((i * 17) % 100) as f64 / 100.0);
            fit.contact_std = Some(0.05);
            if i % 9 == 2 {
                fit.effects = "soil_damping".into();
                fit.soil_loss_factor = Some(0.1);
                fit.soil_loss_factor_std = Some(0.02);
            }
            fit.misfit = Some(1e-4 * (1.0 + ((i * 7) % 97) as f64).powi(2));
            fit.chi2_per_dof = Some(0.5 + ((i * 13) % 89) as f64 / 10.0);
            fit.n_measurements = Some(5);
            let c_p = soil_p_speed(i, soils[i]);
            fit.soil_p_wave_speed_m_per_s = Some(c_p);
            fit.soil_p_wave_speed_std_m_per_s = Some(soil_p_rel_std(i) * c_p);
            fit.soil_s_wave_speed_m_per_s = Some(0.5 * c_p);
            let plastic = is_plastic(specs[i].0);
            fit.soil_s_wave_speed_std_m_per_s = Some(if plastic { 0.05 } else { 0.5 } * 0.5 * c_p);
            let (lb0, lb_slope) = speed_law(i, *base);
            let lb = lb0 + lb_slope * 450.0;
            fit.leak_band_speed_m_per_s = Some(lb);
            fit.leak_band_speed_std_m_per_s = leak_band_rel_std(i).map(|r| r * lb);
            (fit.notes, fit.note_reasons) = if !plastic {
                (
                    "soil_via_cp,contact_undetermined".into(),
                    format!("soil_via_cp: E_m and nu_m known only through c_P = {c_p:.0} m/s\ncontact_undetermined: xi not determined"),
                )
            } else if i % 5 == 0 {
                ("at_bound".into(), "at_bound: nu_m reaches 0.49".into())
            } else {
                (String::new(), String::new())
            };
            if status == FitStatus::Flagged {
                fit.flags = if i % 4 == 1 {
                    "high_misfit,at_bound"
                } else {
                    "high_misfit"
                }
                .into();
                counts.n_flagged += 1;
            } else {
                counts.n_ok += 1;
            }
            let (c0, slope) = speed_law(i, *base);
            STANDARD_GRID_HZ
                .iter()
                .map(|&f| CurvePoint {
                    frequency_hz: f,
                    phase_speed_m_per_s: Some(c0 + slope * f),
                    attenuation_db_per_m: Some(0.002 * f.sqrt()),
                    phase_speed_std_m_per_s: Some(0.004 * (c0 + slope * f)),
                    attenuation_std_db_per_m: Some(0.0002 * f.sqrt()),
                    model_phase_speed_m_per_s: None,
                    model_attenuation_db_per_m: None,
                })
                .collect()
        };
        fit.evaluations = Some(1000);
        insert_fit_with_curves(database.conn_mut(), &fit, &curve).expect("insert fit");
    }
    finish_run(database.conn(), run_id, &counts, RunStatus::Finished).expect("finish run");
    database
}
