//! Leak location across a path of one or more segments (model §11, P84–P87).
//!
//! * [`network`]: the sensors on the network and the path between them;
//! * [`model`]: the predicted delay T(x) from each segment's curve over the correlation band
//!   (P85), its inversion and the error budget (P86), and the table-speed position (P45);
//! * [`gcc`]: the delay from two recordings (generalised cross-correlation, P87);
//! * [`synth::locate`](crate::synth::locate): synthetic leak recordings from the segments' true
//!   soil and contact;
//! * [`jobs`]: the batch file, and the CSV, GeoJSON and GeoPackage outputs.
//!
//! [`Locator`] ties them to a database: it reads the network once and each segment's curve
//! (its fit's, or the soil field's prediction) when a path first needs it.

pub mod gcc;
pub mod jobs;
pub mod model;
pub mod network;

use std::collections::HashMap;
use std::path::PathBuf;

use rusqlite::Connection;

use crate::db::speeds::{speed_curve, CurveSource};
use crate::db::SegmentRecord;
use crate::field::joint::{JointField, Target};
use crate::physics::{ContactMode, Model, Soil, System};
use crate::units::short;
use gcc::{gcc_delay, read_pair, RecordingPair};
use model::{
    band_grid, solve, table_position, DelayModel, ModelPiece, SpeedCurve, TermKind, Weighting,
    MODEL_GRID_POINTS,
};
use nalgebra::DMatrix;
use network::{Network, SensorPath, SensorSpec};

/// Default correlation band, Hz (the leak band).
pub const DEFAULT_BAND_HZ: (f64, f64) = (100.0, 800.0);
/// A coherent band narrower than this (Hz) cannot hold a delay well: with the default band,
/// its low edge is then lowered.
pub const MIN_COHERENT_WIDTH_HZ: f64 = 50.0;
/// The lowest frequency the default band is lowered to, Hz (the fits' curves start at 10 Hz).
pub const LOW_BAND_FLOOR_HZ: f64 = 10.0;
/// The narrowest correlation band, Hz. A band Δf wide gives a correlation whose envelope is
/// about 1/Δf wide (P85): 5 Hz gives 0.2 s, as long as the whole travel time across a 100-m span
/// of plastic main (about 500 m/s), so a narrower band's correlation is a carrier with crests
/// every 1/f and no peak that resolves a delay. It also bounds the work: the crests searched
/// grow as the band's centre over its width.
pub const MIN_BAND_WIDTH_HZ: f64 = 5.0;
/// The highest edge of a correlation band, Hz: the top of the audio range; buried mains carry
/// leak noise a few kHz at most, and the fits' curves end far below.
pub const MAX_BAND_HZ: f64 = 20_000.0;
/// The largest delay (and delay error) a correlation can have, s: the travel time across 3 km
/// of plastic main at 300 m/s, farther than leak noise carries between two sensors.
pub const MAX_DELAY_S: f64 = 10.0;
/// The largest relative error of a span, a fraction: a GIS length wrong by half is no span.
pub const MAX_SPAN_STD_FRACTION: f64 = 0.5;
/// Default relative error of a span measured along GIS geometry (GIS lengths are good to a few
/// per cent, model §11).
pub const DEFAULT_SPAN_STD_FRACTION: f64 = 0.01;

/// Why one correlation cannot be located. Messages name the segment, file or job.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocateError {
    /// The network, a sensor's place, or a segment.
    #[error("{0}")]
    Network(String),
    /// The path.
    #[error("{0}")]
    Path(String),
    /// A segment without a speed.
    #[error("{0}")]
    NoSpeed(String),
    /// The delay.
    #[error("{0}")]
    Delay(String),
    /// The recordings.
    #[error("{0}")]
    Recording(String),
    /// The database.
    #[error("database: {0}")]
    Db(String),
}

/// Settings shared by every job.
#[derive(Debug, Clone, PartialEq)]
pub struct LocateOptions {
    /// Correlation band, Hz (a job may set its own).
    pub band_hz: (f64, f64),
    /// Weighting of the correlation (recordings); a given delay is modelled as a plain
    /// correlator's unless this says PHAT or SCOT.
    pub weighting: Weighting,
    /// Weighting assumed for a given delay.
    pub given_weighting: Weighting,
    /// Map coordinates farther than this from every segment are off the network, m.
    pub snap_tolerance_m: f64,
    /// Relative error of the span's length.
    pub span_std_fraction: f64,
    /// Combine the predicted segments' speed errors with their joint posterior through the soil
    /// field (false: treat every segment's speed error as independent).
    pub joint_speeds: bool,
}

impl Default for LocateOptions {
    fn default() -> Self {
        LocateOptions {
            band_hz: DEFAULT_BAND_HZ,
            weighting: Weighting::Scot,
            given_weighting: Weighting::Plain,
            snap_tolerance_m: network::DEFAULT_SNAP_TOLERANCE_M,
            span_std_fraction: DEFAULT_SPAN_STD_FRACTION,
            joint_speeds: true,
        }
    }
}

/// The delay of a job.
#[derive(Debug, Clone, PartialEq)]
pub enum DelayInput {
    /// Measured by a correlator: t₂ − t₁ and its error, s.
    Given {
        /// Delay, s.
        delay_s: f64,
        /// Its standard error, s.
        std_s: f64,
    },
    /// Two recordings.
    Recordings(RecordingPair),
}

/// One correlation to locate.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// The user's id.
    pub id: String,
    /// Where it was read (file), for messages.
    pub source: PathBuf,
    /// Line of the file (1 = header).
    pub line: u64,
    /// Sensor 1.
    pub sensor1: SensorSpec,
    /// Sensor 2.
    pub sensor2: SensorSpec,
    /// The delay.
    pub delay: DelayInput,
    /// Its own band, Hz.
    pub band_hz: Option<(f64, f64)>,
    /// An explicit path (segment ids from sensor 1's to sensor 2's).
    pub path: Option<Vec<String>>,
}

/// One term of the budget, named.
#[derive(Debug, Clone, PartialEq)]
pub struct BudgetTerm {
    /// `delay`, `span`, or `speed <segment id>`.
    pub name: String,
    /// The segment for a speed term.
    pub segment_id: Option<String>,
    /// Position change for +1σ of the input, m (signed for speeds: the change when the speed
    /// is higher).
    pub shift_m: f64,
}

/// The located leak.
#[derive(Debug, Clone, PartialEq)]
pub struct Located {
    /// The job's id.
    pub job_id: String,
    /// Segment ids of the path, from sensor 1.
    pub path_ids: Vec<String>,
    /// Where each path segment's curve came from.
    pub sources: Vec<CurveSource>,
    /// Span D, m.
    pub span_m: f64,
    /// The segment holding the leak.
    pub leak_segment: String,
    /// Its chainage there, m.
    pub leak_chainage_m: f64,
    /// Distance from sensor 1 along the path, m, and its 95 % interval.
    pub distance_m: f64,
    /// Lower end of the 95 % interval, m.
    pub lo_m: f64,
    /// Upper end.
    pub hi_m: f64,
    /// Standard error, m.
    pub std_m: f64,
    /// The speeds' part of it, m: the speed terms combined with the correlation of predicted
    /// neighbours' errors (P86).
    pub speeds_std_m: f64,
    /// The budget, largest first.
    pub budget: Vec<BudgetTerm>,
    /// What would shrink the largest term.
    pub advice: String,
    /// The correlator's answer with each segment's Korteweg speed, m from sensor 1.
    pub table_distance_m: f64,
    /// The delay used, s, and its error.
    pub delay_s: f64,
    /// Its standard error, s.
    pub delay_std_s: f64,
    /// The correlation band used, Hz.
    pub band_used_hz: (f64, f64),
    /// Why that band.
    pub band_note: String,
    /// The map point (network CRS), when the leak's segment has a line.
    pub point: Option<(f64, f64)>,
    /// The 95 % interval as a line along the pipe.
    pub interval_line: Vec<(f64, f64)>,
    /// Other notes (clamped at a sensor, per-segment speed errors, ...).
    pub notes: Vec<String>,
}

/// The correlation of a path's speed errors by curve, and the correlated pairs (curve a, curve
/// b, ρ).
pub type SpeedCorrelation = (DMatrix<f64>, Vec<(usize, usize, f64)>);

/// Locates correlations on one database's network.
pub struct Locator<'c> {
    conn: &'c Connection,
    /// The network.
    pub network: Network,
    records: Vec<SegmentRecord>,
    curves: HashMap<usize, Result<(CurveSource, SpeedCurve), String>>,
    /// The soil field for joint posteriors (read when a path first has two predicted segments;
    /// `None` inside when the database has no field).
    joint: Option<Option<JointField>>,
    /// Each predicted segment's leak-band speed error and its gradient in the soil (m/s).
    gradients: HashMap<usize, Option<(f64, [f64; 2])>>,
    /// Settings.
    pub options: LocateOptions,
}

impl<'c> Locator<'c> {
    /// Read the inventory and build the junction graph.
    pub fn new(
        conn: &'c Connection,
        options: LocateOptions,
        join_tolerance_m: f64,
    ) -> Result<Locator<'c>, LocateError> {
        let records =
            crate::db::load_segments(conn, None).map_err(|e| LocateError::Db(e.to_string()))?;
        let network = Network::from_records(&records, join_tolerance_m)?;
        Ok(Locator {
            conn,
            network,
            records,
            curves: HashMap::new(),
            joint: None,
            gradients: HashMap::new(),
            options,
        })
    }

    /// The inventory record of segment `i`.
    pub fn record(&self, i: usize) -> &SegmentRecord {
        &self.records[i]
    }

    /// The curve of segment `i` (read once).
    pub fn curve(&mut self, i: usize) -> Result<(CurveSource, SpeedCurve), LocateError> {
        if !self.curves.contains_key(&i) {
            let id = &self.network.segments[i].id;
            let got =
                match speed_curve(self.conn, id) {
                    Err(e) => return Err(LocateError::Db(e.to_string())),
                    Ok(None) => Err(format!(
                        "segment {id} on the path has no speed: no fit and no prediction (run \
                     calibrate, or give it measurements)"
                    )),
                    Ok(Some((src, pts))) => SpeedCurve::from_points(&pts)
                        .map(|c| (src, c))
                        .ok_or_else(|| {
                            format!(
                                "segment {id} on the path has a curve with fewer than two speeds"
                            )
                        }),
                };
            self.curves.insert(i, got);
        }
        self.curves[&i].clone().map_err(LocateError::NoSpeed)
    }

    /// The correlation of the speed errors of the path's segments `segs` (by curve) whose
    /// curves are predictions: their soils' joint posterior (P80) carried to the leak-band speed
    /// by each prediction's gradient ∂c/∂u, ρ_ab = g_aᵀ Cov(u_a, u_b) g_b / (σ_a σ_b). Fitted
    /// speeds' errors are their own fits' and stay independent. `None` when fewer than two
    /// predicted segments can be placed in the field.
    pub fn speed_correlation(
        &mut self,
        segs: &[usize],
        sources: &[CurveSource],
    ) -> Result<Option<SpeedCorrelation>, LocateError> {
        let db = |e: crate::db::DbError| LocateError::Db(e.to_string());
        let predicted: Vec<usize> = (0..segs.len())
            .filter(|&c| sources[c] == CurveSource::Prediction)
            .collect();
        if predicted.len() < 2 || !self.options.joint_speeds {
            return Ok(None);
        }
        if self.joint.is_none() {
            self.joint = Some(JointField::from_db(self.conn).map_err(db)?);
        }
        let mut usable: Vec<(usize, Target, f64, [f64; 2])> = Vec::new();
        for &c in &predicted {
            let s = segs[c];
            if !self.gradients.contains_key(&s) {
                let g = crate::db::field::prediction_for(self.conn, &self.network.segments[s].id)
                    .map_err(db)?
                    .and_then(|(row, _)| {
                        let (_, std) = row.leak_band_speed?;
                        let g = row.leak_band_speed_gradient?;
                        (std > 0.0 && g.iter().all(|v| v.is_finite())).then_some((std, g))
                    });
                self.gradients.insert(s, g);
            }
            let Some(Some(joint)) = self.joint.as_ref() else {
                return Ok(None);
            };
            if let (Some((std, g)), Some(t)) = (
                self.gradients[&s],
                joint.target(&self.network.segments[s].id),
            ) {
                usable.push((c, t, std, g));
            }
        }
        let Some(Some(joint)) = self.joint.as_ref() else {
            return Ok(None);
        };
        if usable.len() < 2 {
            return Ok(None);
        }
        let targets: Vec<Target> = usable.iter().map(|u| u.1).collect();
        let post = joint.posterior(&targets);
        let mut corr = DMatrix::<f64>::identity(segs.len(), segs.len());
        let mut pairs = Vec::new();
        for (i, a) in usable.iter().enumerate() {
            for (j, b) in usable.iter().enumerate().skip(i + 1) {
                let r = (post.cov_of(i, a.3, j, b.3) / (a.2 * b.2)).clamp(-1.0, 1.0);
                corr[(a.0, b.0)] = r;
                corr[(b.0, a.0)] = r;
                pairs.push((a.0, b.0, r));
            }
        }
        Ok(Some((corr, pairs)))
    }

    /// Korteweg's speed of segment `i` (P45); it does not depend on the soil.
    pub fn korteweg(&self, i: usize) -> Result<f64, LocateError> {
        let r = &self.records[i];
        let bad = |e: crate::physics::InputError| {
            LocateError::Network(format!("segment {}: {e}", r.segment_id))
        };
        let sys = System::new(
            r.fluid().map_err(bad)?,
            r.pipe().map_err(bad)?,
            Soil::none(),
            0.0,
            Model::Full,
            ContactMode::default(),
        )
        .map_err(bad)?;
        Ok(crate::physics::dispersion::korteweg_speed(&sys))
    }

    /// The path of a job.
    pub fn path(&self, job: &Job) -> Result<SensorPath, LocateError> {
        let tol = self.options.snap_tolerance_m;
        let s1 = self
            .network
            .place(&job.sensor1, tol)
            .map_err(|e| sensor_err(1, e))?;
        let s2 = self
            .network
            .place(&job.sensor2, tol)
            .map_err(|e| sensor_err(2, e))?;
        match &job.path {
            Some(ids) => self.network.explicit_path(ids, s1, s2),
            None => self.network.route(s1, s2),
        }
    }

    /// Locate one correlation.
    pub fn locate(&mut self, job: &Job) -> Result<Located, LocateError> {
        let path = self.path(job)?;
        let span = path.span_m();
        if span <= 0.0 {
            return Err(LocateError::Path(
                "the two sensors are at the same place (span 0 m)".into(),
            ));
        }
        // The distinct segments of the path and their curves.
        let mut segs: Vec<usize> = Vec::new();
        let mut pieces = Vec::with_capacity(path.pieces.len());
        for p in &path.pieces {
            let c = match segs.iter().position(|&s| s == p.segment) {
                Some(c) => c,
                None => {
                    segs.push(p.segment);
                    segs.len() - 1
                }
            };
            pieces.push(ModelPiece {
                curve: c,
                length_m: p.length_m(),
            });
        }
        let mut curves = Vec::with_capacity(segs.len());
        let mut sources = Vec::with_capacity(segs.len());
        for &s in &segs {
            let (src, c) = self.curve(s)?;
            sources.push(src);
            curves.push(c);
        }
        let requested = job.band_hz.unwrap_or(self.options.band_hz);
        check_band(requested)?;
        let (mut lo, mut hi) = requested;
        for c in &curves {
            let (a, b) = c.range_hz();
            lo = lo.max(a);
            hi = hi.min(b);
        }
        if hi - lo < MIN_BAND_WIDTH_HZ {
            return Err(LocateError::NoSpeed(format!(
                "the curves of the path's segments have {} in common with the band {}–{} Hz \
                 (a correlation needs at least {} Hz)",
                if hi <= lo {
                    "no frequency".to_string()
                } else {
                    format!("only {}–{} Hz", short(lo), short(hi))
                },
                short(requested.0),
                short(requested.1),
                short(MIN_BAND_WIDTH_HZ)
            )));
        }
        let mut band_note = if (lo, hi) == requested {
            format!("{}–{} Hz asked", requested.0, requested.1)
        } else {
            format!(
                "{}–{} Hz asked; {lo:.0}–{hi:.0} Hz is where every segment of the path has a curve",
                requested.0, requested.1
            )
        };
        let refs: Vec<&SpeedCurve> = curves.iter().collect();
        let grid = band_grid((lo, hi), MODEL_GRID_POINTS);
        let ones = vec![1.0; grid.len()];
        let (model, tau, tau_std, band_used) = match &job.delay {
            DelayInput::Given { delay_s, std_s } => {
                check_delay(*delay_s, *std_s)?;
                let plain = self.options.given_weighting == Weighting::Plain;
                let m = DelayModel::new(&grid, &ones, plain, &refs, pieces);
                (m, *delay_s, *std_s, (lo, hi))
            }
            DelayInput::Recordings(pair) => {
                let rec = read_pair(pair, &job.source, job.line, &job.id)?;
                let probe = DelayModel::new(&grid, &ones, false, &refs, pieces.clone());
                let (t0, t1) = (probe.delay(0.0), probe.delay(span));
                let margin = 0.1 * (t0 - t1).abs() + 0.005;
                let search = (t1 - margin, t0 + margin);
                let mut g = gcc_delay(&rec, (lo, hi), self.options.weighting, search);
                // The default band is the metal pipes' leak band; plastic pipes carry leak
                // noise mostly below it. When the default band holds (almost) no coherence,
                // lower its edge to where the curves start, and say so.
                let default_band = job.band_hz.is_none() && requested == DEFAULT_BAND_HZ;
                let narrow = g.as_ref().map_or(true, |d| {
                    d.band_used_hz.1 - d.band_used_hz.0 < MIN_COHERENT_WIDTH_HZ
                });
                let floor = curves
                    .iter()
                    .map(|c| c.range_hz().0)
                    .fold(LOW_BAND_FLOOR_HZ, f64::max);
                let mut widened = None;
                if default_band && narrow && floor < lo {
                    if let Ok(d) = gcc_delay(&rec, (floor, hi), self.options.weighting, search) {
                        let was = match &g {
                            Ok(d) => format!(
                                "coherent only in {:.0}–{:.0} Hz",
                                d.band_used_hz.0, d.band_used_hz.1
                            ),
                            Err(_) => "not coherent".to_string(),
                        };
                        widened = Some(format!(
                            "{}–{} Hz (the default) was {was}, so its low edge was lowered to \
                             {floor:.0} Hz (leak noise in plastic pipes lies mostly below \
                             100 Hz)",
                            requested.0, requested.1
                        ));
                        g = Ok(d);
                    }
                }
                let g = g.map_err(|e| LocateError::Recording(format!("job {}: {e}", job.id)))?;
                band_note = match widened {
                    Some(w) => format!("{w}; {}", g.band_note),
                    None => format!("{band_note}; {}", g.band_note),
                };
                band_note = format!(
                    "{band_note}; {} weighting",
                    self.options.weighting.as_str().to_uppercase()
                );
                let (f, w) = regrid(&g.freqs_hz, &g.weights, MODEL_GRID_POINTS);
                let m = DelayModel::new(&f, &w, false, &refs, pieces);
                (m, g.delay_s, g.delay_std_s, g.band_used_hz)
            }
        };
        let span_std = self.options.span_std_fraction * span;
        let speed_terms: Vec<usize> = (0..segs.len()).collect();
        let mut pos = solve(&model, tau, tau_std, span_std, &speed_terms).map_err(|o| {
            LocateError::Delay(format!(
                "delay {:.6} s is longer than the span allows: the sensors are {span:.1} m \
                 apart along the path ({}), so with these speeds the delay lies between \
                 {:.6} s (leak at sensor 2) and {:.6} s (leak at sensor 1); check the sign \
                 (t(sensor 2) − t(sensor 1)) and the sensors' places",
                tau,
                path_ids(&self.network, &path).join(", "),
                o.t_at_sensor2,
                o.t_at_sensor1
            ))
        })?;
        let mut notes = Vec::new();
        if let Some(s) = pos.at_sensor {
            notes.push(format!(
                "the delay is just beyond the span (within its error and the speeds'): leak put \
                 at sensor {s}"
            ));
        }
        let correlation = self.speed_correlation(&segs, &sources)?;
        let speeds_std_m = match &correlation {
            Some((corr, pairs)) => {
                pos.correlate_speeds(corr, span);
                let id = |c: usize| self.network.segments[segs[c]].id.as_str();
                notes.push(format!(
                    "predicted speeds' errors correlated through the soil field ({}); fitted \
                     speeds' errors independent",
                    pairs
                        .iter()
                        .map(|&(a, b, r)| format!("{}–{} ρ = {r:.2}", id(a), id(b)))
                        .collect::<Vec<_>>()
                        .join(", ")
                ));
                pos.speeds_std_m(Some(corr))
            }
            None => {
                if segs.len() > 1 {
                    notes.push(
                        if sources
                            .iter()
                            .filter(|s| **s == CurveSource::Prediction)
                            .count()
                            > 1
                        {
                            "speed errors treated as independent per segment (no joint posterior \
                             of the predicted segments from the soil field)"
                        } else {
                            "speed errors independent per segment (each fitted speed's error is \
                             its own fit's)"
                        }
                        .into(),
                    );
                }
                pos.speeds_std_m(None)
            }
        };
        for (i, c) in curves.iter().enumerate() {
            if !c.has_std {
                notes.push(format!(
                    "segment {} has no stored speed error; its term is zero",
                    self.network.segments[segs[i]].id
                ));
            }
        }
        let mut budget: Vec<BudgetTerm> = pos
            .terms
            .iter()
            .map(|t| match t.kind {
                TermKind::Delay => BudgetTerm {
                    name: "delay".into(),
                    segment_id: None,
                    shift_m: t.shift_m,
                },
                TermKind::Span => BudgetTerm {
                    name: "span".into(),
                    segment_id: None,
                    shift_m: t.shift_m,
                },
                TermKind::Speed(c) => {
                    let id = self.network.segments[segs[c]].id.clone();
                    BudgetTerm {
                        name: format!("speed {id}"),
                        segment_id: Some(id),
                        shift_m: t.shift_m,
                    }
                }
            })
            .collect();
        budget.sort_by(|a, b| b.shift_m.abs().total_cmp(&a.shift_m.abs()));
        let advice = match budget.first() {
            Some(t) if t.name == "delay" => match job.delay {
                DelayInput::Recordings(_) => "record longer (the delay's error falls as \
                    1/√T), or move the sensors closer to widen the coherent band"
                    .to_string(),
                _ => "a longer or cleaner correlation (the delay's error)".to_string(),
            },
            Some(t) if t.name == "span" => {
                "measure the span on site (a wheel or tape) instead of the GIS length".into()
            }
            Some(t) => format!(
                "measure the wave speed of segment {} (a hydrant test: wavenumbers → calibrate)",
                t.segment_id.as_deref().unwrap_or("")
            ),
            None => String::new(),
        };
        // The correlator's answer with one speed per piece (P45).
        let lengths: Vec<f64> = path.pieces.iter().map(|p| p.length_m()).collect();
        let speeds: Vec<f64> = path
            .pieces
            .iter()
            .map(|p| self.korteweg(p.segment))
            .collect::<Result<_, _>>()?;
        let table = table_position(&lengths, &speeds, tau);
        let (pi, chainage) = path.locate(pos.x_m);
        Ok(Located {
            job_id: job.id.clone(),
            path_ids: segs
                .iter()
                .map(|&s| self.network.segments[s].id.clone())
                .collect(),
            sources,
            span_m: span,
            leak_segment: self.network.segments[path.pieces[pi].segment].id.clone(),
            leak_chainage_m: chainage,
            distance_m: pos.x_m,
            lo_m: pos.lo_m,
            hi_m: pos.hi_m,
            std_m: pos.std_m,
            speeds_std_m,
            budget,
            advice,
            table_distance_m: table,
            delay_s: tau,
            delay_std_s: tau_std,
            band_used_hz: band_used,
            band_note,
            point: self.network.point_on_path(&path, pos.x_m),
            interval_line: self.network.line_on_path(&path, pos.lo_m, pos.hi_m),
            notes,
        })
    }
}

fn sensor_err(n: u8, e: LocateError) -> LocateError {
    match e {
        LocateError::Network(m) => LocateError::Network(format!("sensor {n}: {m}")),
        e => e,
    }
}

fn path_ids(net: &Network, path: &SensorPath) -> Vec<String> {
    path.pieces
        .iter()
        .map(|p| net.segments[p.segment].id.clone())
        .collect()
}

/// A correlation band: `0 < low`, `high ≤` [`MAX_BAND_HZ`], and at least [`MIN_BAND_WIDTH_HZ`]
/// wide. The same check serves `--band` and a jobs file's band columns.
pub fn check_band(b: (f64, f64)) -> Result<(), LocateError> {
    let (lo, hi) = b;
    if lo.is_finite()
        && hi.is_finite()
        && lo > 0.0
        && hi <= MAX_BAND_HZ
        && hi - lo >= MIN_BAND_WIDTH_HZ
    {
        Ok(())
    } else {
        Err(LocateError::Delay(format!(
            "band {}–{} Hz: expected 0 < low < high ≤ {} Hz, at least {} Hz wide (a narrower \
             band's correlation has no peak to resolve a delay by)",
            short(lo),
            short(hi),
            short(MAX_BAND_HZ),
            short(MIN_BAND_WIDTH_HZ)
        )))
    }
}

/// A correlator's delay and its standard error: finite, the error non-negative, both at most
/// [`MAX_DELAY_S`] in size. The same check serves `--delay`, `--delay-std` and a jobs file's
/// `delay_s`, `delay_std_s`.
pub fn check_delay(delay_s: f64, std_s: f64) -> Result<(), LocateError> {
    let within = |v: f64| v.is_finite() && v.abs() <= MAX_DELAY_S;
    if within(delay_s) && within(std_s) && std_s >= 0.0 {
        Ok(())
    } else {
        Err(LocateError::Delay(format!(
            "delay {} s ± {} s: expected a delay of at most ±{} s and an error of 0 – {} s",
            short(delay_s),
            short(std_s),
            short(MAX_DELAY_S),
            short(MAX_DELAY_S)
        )))
    }
}

/// Average (f, w) samples into at most `n` equal cells (each cell's mean frequency and weight).
fn regrid(f: &[f64], w: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    if f.len() <= n {
        return (f.to_vec(), w.to_vec());
    }
    let per = f.len().div_ceil(n);
    f.chunks(per)
        .zip(w.chunks(per))
        .map(|(a, b)| {
            (
                a.iter().sum::<f64>() / a.len() as f64,
                b.iter().sum::<f64>() / b.len() as f64,
            )
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regrid_keeps_the_mean() {
        let f: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let (g, w) = regrid(&f, &f, 5);
        assert_eq!(g, vec![0.5, 2.5, 4.5, 6.5, 8.5]);
        assert_eq!(w, g);
    }
}
