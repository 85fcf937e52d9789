//! The whole field chain on a synthetic network, judged against its truth: hydrant-test
//! recordings of the metal pipes ([`super::record_network_segments`]) → their WAV files
//! and layout → `pipewave wavenumbers` ([`crate::recordings::analyse_segment`],
//! [`write_measurements`]) →
//! `import` and `calibrate` → the fitted soil's compressional speed c_P against the truth
//! ([`crate::synth::network::recovery::compare`]).
//!
//! The recordings are those of `synth --recordings`: the seed layout with sensors at
//! [`crate::synth::recordings::sensor_range_m`] (20–80 m on metals), sensor noise
//! [`crate::synth::recordings::DEFAULT_NOISE_FRACTION`] of the source channel, 8 kHz.
//!
//! With [`Feed::Recordings`] the fit sees only what a user would give it: the inventory
//! (`segments.csv`) and the measurements written by the wavenumbers step; the truth is read
//! only to judge the result. The other [`Feed`]s are controls that put the truth into the
//! measurements on purpose, to tell the errors of the wavenumbers step from those of the fit.
//! The acceptance of the wavenumbers step: "the resulting measurements calibrate without a
//! failed fit, and give c_P within its 2σ for ≥ 90 % of metal pipes".

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::batch::{calibrate, CalibrateOptions};
use crate::db::{self, Database, FitRow, FitStatus, ImportOptions, ImportSource, SegmentRecord};
use crate::physics::Material;
use crate::recordings::{
    analyse_segment, read_layout, write_measurements, BandEstimate, EstimateOptions,
};
use crate::stats::normal;
use crate::synth::network::recovery::{compare, RecoveryReport};
use crate::synth::network::{NetworkTables, MEASUREMENTS_CSV, SEGMENTS_CSV};
use crate::synth::recordings::{record_network_segments, write_recordings, TruthCurve, LAYOUT_CSV};
use crate::synth::{generate, SynthOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What to record and fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainSpec {
    /// Seed of the synthetic network (and, through each segment's id, of its recordings).
    pub seed: u64,
    /// Metal pipes (CI, DI, ST) to record: the first ones of the network.
    pub metal_pipes: usize,
    /// Length of each recording, s.
    pub seconds: f64,
    /// Calibrate's worker threads.
    pub jobs: usize,
    /// What the fit is given at the bands the wavenumbers step kept.
    pub feed: Feed,
}

/// What the fit is given: the estimates from the recordings, or a control that keeps their
/// frequencies and standard errors and replaces the values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feed {
    /// The wavenumbers step's estimates (the chain as a user runs it).
    Recordings,
    /// Control: the truth, plus independent Gaussian errors of the stated σ (seeded). What
    /// the fit's c_P coverage would be if the band errors were exactly as stated and independent.
    Ideal(u64),
    /// Control: the truth's Re k1, the recordings' attenuation.
    TruthK,
    /// Control: the recordings' Re k1, the truth's attenuation.
    TruthAttenuation,
}

/// One recorded and fitted pipe.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainPipe {
    /// Asset id.
    pub segment_id: String,
    /// Material.
    pub material: Material,
    /// Outside diameter, mm.
    pub od_mm: f64,
    /// Sensor positions, m.
    pub positions_m: Vec<f64>,
    /// Bands the wavenumbers step kept (what was imported).
    pub bands: Vec<BandEstimate>,
    /// The wavenumber the recordings were made with (to judge the bands; the fit never sees it).
    pub truth: TruthCurve,
    /// The true c_P, m/s (P63, at the inventory's soil density).
    pub cp_true: f64,
    /// The latest fit (`None` when calibrate stored none).
    pub fit: Option<FitRow>,
}

impl ChainPipe {
    /// Mean over the bands of (estimate − truth) / σ: (Re k1, attenuation); NaN without bands.
    pub fn band_bias_z(&self) -> (f64, f64) {
        let (mut zk, mut za, mut n) = (0.0, 0.0, 0usize);
        for b in &self.bands {
            if let Some(k) = self.truth.at(b.frequency_hz) {
                zk += (b.k_re - k.re) / b.k_re_std;
                za += (b.attenuation + k.im) / b.attenuation_std;
                n += 1;
            }
        }
        (zk / n as f64, za / n as f64)
    }

    /// (c_P,fit − c_P,true) / σ(c_P,fit), or NaN without a fit or a standard error.
    pub fn cp_z(&self) -> f64 {
        match self
            .fit
            .as_ref()
            .map(|f| (f.soil_p_wave_speed_m_per_s, f.soil_p_wave_speed_std_m_per_s))
        {
            Some((Some(v), Some(s))) => (v - self.cp_true) / s,
            _ => f64::NAN,
        }
    }
}

/// The result of [`run_chain`].
#[derive(Debug, Clone)]
pub struct ChainResult {
    /// Every recorded pipe, in network order.
    pub pipes: Vec<ChainPipe>,
    /// Pipes whose recordings the wavenumbers step could not use (id, message).
    pub unusable: Vec<(String, String)>,
    /// The fits against the truth.
    pub recovery: RecoveryReport,
}

/// Network segments generated per metal pipe asked for (metals are about half of the
/// synthetic network's mix, README of sample_network).
const SEGMENTS_PER_METAL: usize = 3;

/// Run the chain in `dir` (which receives `recordings/`, `measurements.csv`, `segments.csv`
/// and the database `chain.sqlite`).
pub fn run_chain(spec: &ChainSpec, dir: &Path) -> Result<ChainResult, String> {
    let opts = SynthOptions {
        segments: SEGMENTS_PER_METAL * spec.metal_pipes + 10,
        seed: spec.seed,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    };
    let network: Vec<_> = generate(&opts)
        .into_iter()
        .filter(|s| {
            matches!(
                s.material,
                Material::CastIron | Material::DuctileIron | Material::Steel
            )
        })
        .take(spec.metal_pipes)
        .collect();
    if network.len() < spec.metal_pipes {
        return Err(format!(
            "the network of seed {} has only {} metal pipes",
            spec.seed,
            network.len()
        ));
    }
    let ids: Vec<String> = network.iter().map(|s| s.id.clone()).collect();
    // 1. Recordings, written as a field team would bring them back.
    let recorded = record_network_segments(&network, &opts, &ids, spec.seconds)?;
    let rec_dir = dir.join("recordings");
    write_recordings(&rec_dir, &recorded).map_err(|e| e.to_string())?;
    // 2. `wavenumbers`.
    let layout = read_layout(&rec_dir.join(LAYOUT_CSV)).map_err(|e| {
        e.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    })?;
    let mut results = Vec::new();
    let mut unusable = Vec::new();
    for seg in &layout.segments {
        match analyse_segment(&layout.path, seg, &EstimateOptions::default(), &|_| {}) {
            Ok(r) => results.push(r),
            Err(e) => unusable.push((seg.segment_id.clone(), e.to_string())),
        }
    }
    if spec.feed != Feed::Recordings {
        let mut rng = match spec.feed {
            Feed::Ideal(seed) => ChaCha8Rng::seed_from_u64(seed),
            _ => ChaCha8Rng::seed_from_u64(0),
        };
        for r in &mut results {
            let Some(rec) = recorded.iter().find(|x| x.segment_id == r.segment_id) else {
                continue;
            };
            for b in &mut r.bands {
                let Some(k) = rec.recording.truth.at(b.frequency_hz) else {
                    continue;
                };
                match spec.feed {
                    Feed::Ideal(_) => {
                        b.k_re = k.re + b.k_re_std * normal(&mut rng);
                        b.attenuation = (-k.im + b.attenuation_std * normal(&mut rng)).max(0.0);
                    }
                    Feed::TruthK => b.k_re = k.re,
                    Feed::TruthAttenuation => b.attenuation = -k.im,
                    Feed::Recordings => {}
                }
            }
        }
    }
    // 3. `import` and `calibrate`: the inventory and the measurements only (`write_dir`
    // writes an empty measurements.csv, replaced by the wavenumbers step's).
    let tables = NetworkTables::from_synth(&network, opts.srid);
    let inventory = NetworkTables {
        segments: tables
            .segments
            .iter()
            .map(|s| SegmentRecord {
                measurements: Vec::new(),
                ..s.clone()
            })
            .collect(),
        truth: Vec::new(),
    };
    inventory.write_dir(dir).map_err(|e| e.to_string())?;
    write_measurements(&dir.join(MEASUREMENTS_CSV), &results, "chain")
        .map_err(|e| e.to_string())?;
    let mut database = Database::open(dir.join("chain.sqlite")).map_err(|e| e.to_string())?;
    let src = |name: &str| ImportSource::from_path(&dir.join(name)).map_err(|e| e.to_string());
    let report = db::import(
        database.conn_mut(),
        Some(&src(SEGMENTS_CSV)?),
        Some(&src(MEASUREMENTS_CSV)?),
        ImportOptions::default(),
    )
    .map_err(|e| e.to_string())?;
    if let Some(e) = report.errors.first() {
        return Err(format!("import: {e}"));
    }
    let copts = CalibrateOptions {
        jobs: Some(spec.jobs.max(1)),
        ..CalibrateOptions::default()
    };
    calibrate(
        database.conn_mut(),
        &copts,
        &mut (),
        &AtomicBool::new(false),
    )
    .map_err(|e| e.to_string())?;
    let fits = db::latest_fits(database.conn(), None).map_err(|e| e.to_string())?;
    // 4. Judge against the truth.
    let density: HashMap<String, f64> = network
        .iter()
        .map(|s| (s.id.clone(), s.soil_density))
        .collect();
    let recovery = compare(&fits, &tables.truth, &density);
    let pipes = network
        .iter()
        .zip(&recorded)
        .map(|(s, rec)| {
            let r = results.iter().find(|r| r.segment_id == s.id);
            let (cp_true, _) =
                crate::physics::soil::soil_speeds(s.soil_modulus, s.soil_poisson, s.soil_density);
            ChainPipe {
                segment_id: s.id.clone(),
                material: s.material,
                od_mm: s.size.od_mm,
                positions_m: rec.positions_m.clone(),
                bands: r.map(|r| r.bands.clone()).unwrap_or_default(),
                truth: rec.recording.truth.clone(),
                cp_true,
                fit: fits.iter().find(|f| f.segment_id == s.id).cloned(),
            }
        })
        .collect();
    Ok(ChainResult {
        pipes,
        unusable,
        recovery,
    })
}

impl ChainResult {
    /// Pipes whose fit failed or is missing.
    pub fn failed(&self) -> usize {
        self.pipes
            .iter()
            .filter(|p| p.fit.as_ref().is_none_or(|f| f.status == FitStatus::Failed))
            .count()
    }
}
