//! A network directory as `pipewave run` reads it: `segments.csv` and `measurements.csv` in the
//! formats of docs/interface.md, and, for synthetic networks, `truth.csv` with the soil that
//! made the data.
//!
//! * [`NetworkTables`]: the rows of the three files; from a synthetic network
//!   ([`NetworkTables::from_synth`]) plus the published field cases ([`published`]), written as
//!   CSV ([`NetworkTables::write_dir`]).
//! * [`read_truth`]: `truth.csv` back, for [`recovery`].

pub mod published;
pub mod recovery;

use std::path::{Path, PathBuf};

use crate::db::wkt::LineString;
use crate::db::{MeasurementRecord, SegmentRecord};
use crate::synth::{SynthSegment, FIRST_CAMPAIGN, SECOND_CAMPAIGN};

/// File names inside a network directory.
pub const SEGMENTS_CSV: &str = "segments.csv";
/// Field wavenumbers.
pub const MEASUREMENTS_CSV: &str = "measurements.csv";
/// The truth of a synthetic network.
pub const TRUTH_CSV: &str = "truth.csv";

/// The `source` of a synthetic segment in `truth.csv`.
pub const SOURCE_SYNTHETIC: &str = "synthetic";

/// One row of `truth.csv`: what made a segment's data. Blank where unknown (the published
/// field cases).
#[derive(Debug, Clone, PartialEq)]
pub struct TruthRow {
    /// Segment.
    pub segment_id: String,
    /// `synthetic`, or `published: <reference>`.
    pub source: String,
    /// Soil class.
    pub soil_type: Option<String>,
    /// True soil Young's modulus E_m, Pa.
    pub soil_youngs_modulus_pa: Option<f64>,
    /// True soil Poisson's ratio ν_m.
    pub soil_poisson: Option<f64>,
    /// True contact coefficient ξ.
    pub contact: Option<f64>,
    /// Hidden effect (an effect name), if any.
    pub hidden_effect: Option<String>,
    /// Its value.
    pub hidden_effect_value: Option<f64>,
    /// Deliberate defect (`outlier`, `attenuation_in_db`, `wrong_material`,
    /// `too_few_measurements`), if any.
    pub defect: Option<String>,
    /// Soil zone, if any.
    pub soil_zone: Option<String>,
    /// The zone's true E_m, Pa (the segment's soil scatters about it).
    pub zone_soil_youngs_modulus_pa: Option<f64>,
    /// The zone's true ν_m.
    pub zone_soil_poisson: Option<f64>,
    /// True mean phase speed over the leak band 100–800 Hz, m/s (the fits' definition).
    pub leak_band_speed_m_per_s: Option<f64>,
    /// The same pipe's leak-band speed in the table soil (model §7.12), m/s.
    pub table_leak_band_speed_m_per_s: Option<f64>,
    /// Whether the segment's measurements are in measurements.csv.
    pub measured: Option<bool>,
    /// Geological unit (`U1`, `U2`, …), if the network has units.
    pub geological_unit: Option<String>,
    /// Whether the inventory's `soil_type` differs from the true class (`soil_type` here).
    pub label_wrong: Option<bool>,
    /// What changed between the two campaigns (`none`, `soil_change`, `air_in_water`,
    /// `wall_thinning`, `pipe_loss`), for a re-measured segment of `synth --campaigns 2`.
    pub change_effect: Option<String>,
    /// The changed parameter's new value ([`crate::synth::SecondCampaign::change_value`]).
    pub change_value: Option<f64>,
    /// True leak-band speed at the first campaign, m/s (as `leak_band_speed_m_per_s`).
    pub leak_band_speed_before_m_per_s: Option<f64>,
    /// True leak-band speed at the second campaign, m/s.
    pub leak_band_speed_after_m_per_s: Option<f64>,
    /// Detectability z of the change at the stated noise ([`crate::synth::change_z`]).
    pub change_z: Option<f64>,
}

impl TruthRow {
    /// A row whose truth is unknown.
    pub fn unknown(segment_id: &str, source: &str) -> TruthRow {
        TruthRow {
            segment_id: segment_id.to_string(),
            source: source.to_string(),
            soil_type: None,
            soil_youngs_modulus_pa: None,
            soil_poisson: None,
            contact: None,
            hidden_effect: None,
            hidden_effect_value: None,
            defect: None,
            soil_zone: None,
            zone_soil_youngs_modulus_pa: None,
            zone_soil_poisson: None,
            leak_band_speed_m_per_s: None,
            table_leak_band_speed_m_per_s: None,
            measured: None,
            geological_unit: None,
            label_wrong: None,
            change_effect: None,
            change_value: None,
            leak_band_speed_before_m_per_s: None,
            leak_band_speed_after_m_per_s: None,
            change_z: None,
        }
    }
}

/// The three tables of a network directory: the inventory records (the one type the database
/// stores, each with its measurements) and the truth.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetworkTables {
    /// `segments.csv`, and `measurements.csv` from each record's measurements.
    pub segments: Vec<SegmentRecord>,
    /// `truth.csv`.
    pub truth: Vec<TruthRow>,
}

/// Writing a network directory failed.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// A file could not be written or read.
    #[error("cannot {action} {}", path.display())]
    Io {
        /// `write`, `read`, `create the directory`.
        action: &'static str,
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A CSV row could not be read.
    #[error("{}:{line}: {message}", path.display())]
    Row {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
}

impl NetworkTables {
    /// The tables of a synthetic network in EPSG:`srid`. Pipes use the material's typical
    /// properties (no overrides), as [`crate::synth::generate`] does. A network with a second
    /// campaign ([`SynthSegment::second`]) has both, named [`FIRST_CAMPAIGN`] and
    /// [`SECOND_CAMPAIGN`] and dated ([`campaign_date`]); one without keeps the campaign
    /// `synthetic`, undated.
    pub fn from_synth(segments: &[SynthSegment], srid: u32) -> NetworkTables {
        let mut t = NetworkTables::default();
        let two = segments.iter().any(|s| s.second.is_some());
        let measured = segments.iter().filter(|s| s.measured).count();
        let mut j = 0usize;
        for s in segments {
            let record = |m: &crate::synth::SynthMeasurement,
                          campaign: &str,
                          measured_on: Option<String>| MeasurementRecord {
                omega_rad_s: crate::units::hz_to_omega(m.frequency_hz),
                frequency_hz: m.frequency_hz,
                k_re_rad_per_m: m.k_re,
                attenuation_np_per_m: m.attenuation,
                k_re_std: Some(m.k_re_std),
                attenuation_std: Some(m.attenuation_std),
                measured_on,
                campaign: Some(campaign.into()),
                note: None,
            };
            let mut measurements: Vec<MeasurementRecord> = Vec::new();
            if s.measured {
                if two {
                    let first = campaign_date(2026, j, measured);
                    let second = campaign_date(2027, j, measured);
                    measurements.extend(
                        s.measurements
                            .iter()
                            .map(|m| record(m, FIRST_CAMPAIGN, Some(first.clone()))),
                    );
                    measurements.extend(s.second.iter().flat_map(|c| {
                        c.measurements
                            .iter()
                            .map(|m| record(m, SECOND_CAMPAIGN, Some(second.clone())))
                    }));
                } else {
                    measurements
                        .extend(s.measurements.iter().map(|m| record(m, "synthetic", None)));
                }
                j += 1;
            }
            let geometry = (s.geometry.len() >= 2).then(|| LineString {
                points: s
                    .geometry
                    .iter()
                    .map(|&(x, y)| (round_to(x, 2), round_to(y, 2)))
                    .collect(),
            });
            let rec = SegmentRecord {
                length_m: Some(round_to(s.length_m, 2)),
                soil_type: Some(s.soil_label.to_string()),
                install_year: Some(i64::from(s.install_year)),
                soil_zone: s.soil_zone.clone(),
                srid: geometry.as_ref().map(|_| i64::from(srid)),
                geometry_wkt: geometry.map(|g| g.to_wkt()),
                measurements,
                ..SegmentRecord::new(
                    &s.id,
                    s.material,
                    s.size.od_mm,
                    s.size.wall_mm,
                    s.soil_density,
                )
            };
            t.segments.push(rec);
            t.truth.push(TruthRow {
                segment_id: s.id.clone(),
                source: SOURCE_SYNTHETIC.to_string(),
                soil_type: Some(s.soil_type.to_string()),
                soil_youngs_modulus_pa: Some(s.soil_modulus),
                soil_poisson: Some(s.soil_poisson),
                contact: Some(s.contact),
                hidden_effect: s.hidden.map(|(e, _)| e.name().to_string()),
                hidden_effect_value: s.hidden.map(|(_, v)| v),
                defect: Some(s.defect.as_str())
                    .filter(|d| !d.is_empty())
                    .map(str::to_string),
                soil_zone: s.soil_zone.clone(),
                zone_soil_youngs_modulus_pa: s.zone_soil.map(|z| z.0),
                zone_soil_poisson: s.zone_soil.map(|z| z.1),
                leak_band_speed_m_per_s: s.leak_band_speed,
                table_leak_band_speed_m_per_s: s.table_leak_band_speed,
                measured: Some(s.measured),
                geological_unit: s.unit.map(unit_name),
                label_wrong: Some(s.soil_label != s.soil_type),
                change_effect: s.second.as_ref().map(|c| c.change.as_str().to_string()),
                change_value: s.second.as_ref().and_then(|c| c.change_value),
                leak_band_speed_before_m_per_s: s.second.as_ref().and(s.leak_band_speed),
                leak_band_speed_after_m_per_s: s
                    .second
                    .as_ref()
                    .and_then(|c| c.leak_band_speed_after),
                change_z: s.second.as_ref().map(|c| c.change_z),
            });
        }
        t
    }

    /// Every synthetic segment's measurements, measured or not, under campaign `campaign`:
    /// what a later campaign would measure (the records carry the inventory too, but only
    /// [`NetworkTables::measurements_csv`] is meant to be written).
    pub fn campaign(segments: &[SynthSegment], campaign: &str) -> NetworkTables {
        let all: Vec<SynthSegment> = segments
            .iter()
            .map(|s| SynthSegment {
                measured: true,
                second: None,
                ..s.clone()
            })
            .collect();
        let mut t = NetworkTables::from_synth(&all, 0);
        for rec in &mut t.segments {
            for m in &mut rec.measurements {
                m.campaign = Some(campaign.to_string());
            }
        }
        t
    }

    /// Append a published case.
    pub fn push_published(&mut self, case: published::PublishedCase) {
        self.segments.push(case.segment);
        self.truth.push(case.truth);
    }

    /// Number of measurement rows.
    pub fn measurement_count(&self) -> usize {
        self.segments.iter().map(|s| s.measurements.len()).sum()
    }

    /// `segments.csv` as text (docs/interface.md column order; `soil_zone` only when some segment
    /// has one, the fluid columns only when some segment overrides the water).
    pub fn segments_csv(&self) -> String {
        let zoned = self.segments.iter().any(|s| s.soil_zone.is_some());
        let fluid = self
            .segments
            .iter()
            .any(|s| s.fluid_density_kg_m3.is_some() || s.fluid_bulk_modulus_pa.is_some());
        let mut header = vec![
            "segment_id",
            "material",
            "outer_diameter_mm",
            "wall_thickness_mm",
            "soil_density_kg_m3",
            "pipe_youngs_modulus_pa",
            "pipe_poisson",
            "pipe_density_kg_m3",
            "pipe_loss_factor",
            "length_m",
            "soil_type",
            "install_year",
            "geometry_wkt",
            "srid",
        ];
        if fluid {
            header.extend(["fluid_density_kg_m3", "fluid_bulk_modulus_pa"]);
        }
        if zoned {
            header.push("soil_zone");
        }
        csv_text(
            header,
            self.segments.iter().map(|s| {
                let mut row = vec![
                    s.segment_id.clone(),
                    s.material.code().to_string(),
                    s.outer_diameter_mm.to_string(),
                    s.wall_thickness_mm.to_string(),
                    s.soil_density_kg_m3.to_string(),
                    opt(s.pipe_youngs_modulus_pa),
                    opt(s.pipe_poisson),
                    opt(s.pipe_density_kg_m3),
                    opt(s.pipe_loss_factor),
                    opt(s.length_m),
                    s.soil_type.clone().unwrap_or_default(),
                    s.install_year.map(|y| y.to_string()).unwrap_or_default(),
                    s.geometry_wkt.clone().unwrap_or_default(),
                    s.srid.map(|v| v.to_string()).unwrap_or_default(),
                ];
                if fluid {
                    row.extend([opt(s.fluid_density_kg_m3), opt(s.fluid_bulk_modulus_pa)]);
                }
                if zoned {
                    row.push(s.soil_zone.clone().unwrap_or_default());
                }
                row
            }),
        )
    }

    /// `measurements.csv` as text. The file gives the frequency once, in the unit it was given
    /// in: a record holds both f and ω = 2πf, the given one short (`224`, `3121.958`) and the
    /// derived one with 16–17 digits, so the shorter decimal form is written; it reads back to
    /// the same record.
    /// The `measured_on` column is written only when some measurement has a date.
    pub fn measurements_csv(&self) -> String {
        let dated = self
            .segments
            .iter()
            .any(|s| s.measurements.iter().any(|m| m.measured_on.is_some()));
        let mut header = vec![
            "segment_id",
            "frequency_hz",
            "omega_rad_s",
            "k_re_rad_per_m",
            "attenuation_np_per_m",
            "k_re_std",
            "attenuation_std",
        ];
        if dated {
            header.push("measured_on");
        }
        header.push("campaign");
        csv_text(
            header,
            self.segments.iter().flat_map(|s| {
                s.measurements.iter().map(|m| {
                    let (f, w) = (m.frequency_hz.to_string(), m.omega_rad_s.to_string());
                    let (f, w) = if w.len() < f.len() {
                        (String::new(), w)
                    } else {
                        (f, String::new())
                    };
                    let mut row = vec![
                        s.segment_id.clone(),
                        f,
                        w,
                        m.k_re_rad_per_m.to_string(),
                        m.attenuation_np_per_m.to_string(),
                        opt(m.k_re_std),
                        opt(m.attenuation_std),
                    ];
                    if dated {
                        row.push(m.measured_on.clone().unwrap_or_default());
                    }
                    row.push(m.campaign.clone().unwrap_or_default());
                    row
                })
            }),
        )
    }

    /// `truth.csv` as text.
    pub fn truth_csv(&self) -> String {
        let zoned = self.truth.iter().any(|t| t.soil_zone.is_some());
        let mut header = vec![
            "segment_id",
            "source",
            "soil_type",
            "soil_youngs_modulus_pa",
            "soil_poisson",
            "contact",
            "hidden_effect",
            "hidden_effect_value",
            "defect",
        ];
        let united = self.truth.iter().any(|t| t.geological_unit.is_some());
        header.extend([
            "leak_band_speed_m_per_s",
            "table_leak_band_speed_m_per_s",
            "measured",
            "label_wrong",
        ]);
        if united {
            header.push("geological_unit");
        }
        if zoned {
            header.extend([
                "soil_zone",
                "zone_soil_youngs_modulus_pa",
                "zone_soil_poisson",
            ]);
        }
        let changed = self.truth.iter().any(|t| t.change_effect.is_some());
        if changed {
            header.extend([
                "change_effect",
                "change_value",
                "leak_band_speed_before_m_per_s",
                "leak_band_speed_after_m_per_s",
                "change_z",
            ]);
        }
        csv_text(
            header,
            self.truth.iter().map(|t| {
                let mut row = vec![
                    t.segment_id.clone(),
                    t.source.clone(),
                    t.soil_type.clone().unwrap_or_default(),
                    opt(t.soil_youngs_modulus_pa),
                    opt(t.soil_poisson),
                    opt(t.contact),
                    t.hidden_effect.clone().unwrap_or_default(),
                    opt(t.hidden_effect_value),
                    t.defect.clone().unwrap_or_default(),
                ];
                row.extend([
                    opt(t.leak_band_speed_m_per_s),
                    opt(t.table_leak_band_speed_m_per_s),
                    flag(t.measured),
                    flag(t.label_wrong),
                ]);
                if united {
                    row.push(t.geological_unit.clone().unwrap_or_default());
                }
                if zoned {
                    row.extend([
                        t.soil_zone.clone().unwrap_or_default(),
                        opt(t.zone_soil_youngs_modulus_pa),
                        opt(t.zone_soil_poisson),
                    ]);
                }
                if changed {
                    row.extend([
                        t.change_effect.clone().unwrap_or_default(),
                        opt(t.change_value),
                        opt(t.leak_band_speed_before_m_per_s),
                        opt(t.leak_band_speed_after_m_per_s),
                        opt(t.change_z),
                    ]);
                }
                row
            }),
        )
    }

    /// Write `segments.csv`, `measurements.csv` and `truth.csv` into `dir` (created if
    /// missing; existing files are replaced).
    pub fn write_dir(&self, dir: &Path) -> Result<(), NetworkError> {
        std::fs::create_dir_all(dir).map_err(|source| NetworkError::Io {
            action: "create the directory",
            path: dir.to_path_buf(),
            source,
        })?;
        for (name, body) in [
            (SEGMENTS_CSV, self.segments_csv()),
            (MEASUREMENTS_CSV, self.measurements_csv()),
            (TRUTH_CSV, self.truth_csv()),
        ] {
            let path = dir.join(name);
            crate::outfile::write_bytes(&path, crate::outfile::Contents::Plain, body.as_bytes())
                .map_err(|e| NetworkError::Io {
                    action: "write",
                    path,
                    source: std::io::Error::other(e),
                })?;
        }
        Ok(())
    }
}

/// The date segment `j` of the `n` measured ones was measured in the campaign of `year`: the
/// crew works through the network in order over four weeks of May, from the 4th to the 27th
/// (24 days whatever the network's size), so both campaigns' dates are the same day a year
/// apart and the later campaign is each segment's latest (docs/interface.md, "Campaigns keep
/// their history").
pub fn campaign_date(year: i32, j: usize, n: usize) -> String {
    let day = 4 + (j * 24) / n.max(1);
    format!("{year}-05-{day:02}")
}

/// `v` rounded to `digits` decimals (coordinates and lengths to the centimetre).
fn round_to(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

/// A number as the shortest decimal that reads back to the same `f64`, or blank.
fn opt(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// A yes/no as `1` / `0`, or blank.
fn flag(v: Option<bool>) -> String {
    v.map(|b| if b { "1" } else { "0" }.to_string())
        .unwrap_or_default()
}

/// Name of geological unit `u` in truth.csv: `U1`, `U2`, …
pub fn unit_name(u: usize) -> String {
    format!("U{}", u + 1)
}

/// A CSV file as text: the header, then the rows (cells quoted by the `csv` crate where they
/// hold a comma, quote or line break).
fn csv_text(header: Vec<&str>, rows: impl IntoIterator<Item = Vec<String>>) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    // Writing to memory cannot fail.
    let _ = w.write_record(&header);
    for row in rows {
        let _ = w.write_record(&row);
    }
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// Read `truth.csv`. Blank cells are `None`.
pub fn read_truth(path: &Path) -> Result<Vec<TruthRow>, NetworkError> {
    let mut rdr = csv::Reader::from_path(path).map_err(|e| NetworkError::Row {
        path: path.to_path_buf(),
        line: 1,
        message: e.to_string(),
    })?;
    let headers = rdr
        .headers()
        .map_err(|e| NetworkError::Row {
            path: path.to_path_buf(),
            line: 1,
            message: e.to_string(),
        })?
        .clone();
    let col = |name: &str| headers.iter().position(|h| h.trim() == name);
    let id_col = col("segment_id").ok_or_else(|| NetworkError::Row {
        path: path.to_path_buf(),
        line: 1,
        message: "no column segment_id".into(),
    })?;
    let mut out = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| NetworkError::Row {
            path: path.to_path_buf(),
            line: e.position().map(|p| p.line()).unwrap_or(0),
            message: e.to_string(),
        })?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        let cell = |name: &str| {
            col(name)
                .and_then(|i| rec.get(i))
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(str::to_string)
        };
        let num = |name: &str| -> Result<Option<f64>, NetworkError> {
            cell(name)
                .map(|s| {
                    s.parse::<f64>().map_err(|_| NetworkError::Row {
                        path: path.to_path_buf(),
                        line,
                        message: format!("column {name}: '{s}' is not a number"),
                    })
                })
                .transpose()
        };
        let yes_no = |name: &str| -> Result<Option<bool>, NetworkError> {
            cell(name)
                .map(|s| match s.as_str() {
                    "1" => Ok(true),
                    "0" => Ok(false),
                    _ => Err(NetworkError::Row {
                        path: path.to_path_buf(),
                        line,
                        message: format!("column {name}: '{s}' is not 0 or 1"),
                    }),
                })
                .transpose()
        };
        out.push(TruthRow {
            segment_id: rec.get(id_col).unwrap_or("").trim().to_string(),
            source: cell("source").unwrap_or_default(),
            soil_type: cell("soil_type"),
            soil_youngs_modulus_pa: num("soil_youngs_modulus_pa")?,
            soil_poisson: num("soil_poisson")?,
            contact: num("contact")?,
            hidden_effect: cell("hidden_effect"),
            hidden_effect_value: num("hidden_effect_value")?,
            defect: cell("defect"),
            soil_zone: cell("soil_zone"),
            zone_soil_youngs_modulus_pa: num("zone_soil_youngs_modulus_pa")?,
            zone_soil_poisson: num("zone_soil_poisson")?,
            leak_band_speed_m_per_s: num("leak_band_speed_m_per_s")?,
            table_leak_band_speed_m_per_s: num("table_leak_band_speed_m_per_s")?,
            measured: yes_no("measured")?,
            geological_unit: cell("geological_unit"),
            label_wrong: yes_no("label_wrong")?,
            change_effect: cell("change_effect"),
            change_value: num("change_value")?,
            leak_band_speed_before_m_per_s: num("leak_band_speed_before_m_per_s")?,
            leak_band_speed_after_m_per_s: num("leak_band_speed_after_m_per_s")?,
            change_z: num("change_z")?,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{generate, SynthOptions};

    #[test]
    fn synthetic_tables_have_one_row_per_segment_and_measurement() {
        let net = generate(&SynthOptions {
            segments: 5,
            seed: 3,
            defect_fraction: 0.0,
            ..Default::default()
        });
        let t = NetworkTables::from_synth(&net, 27700);
        assert_eq!(t.segments.len(), 5);
        assert_eq!(t.truth.len(), 5);
        assert_eq!(
            t.measurement_count(),
            net.iter().map(|s| s.measurements.len()).sum::<usize>()
        );
        let csv = t.segments_csv();
        let first = csv.lines().nth(1).unwrap();
        assert!(first.contains("\"LINESTRING ("), "{first}");
        assert!(first.ends_with(",27700"), "{first}");
        // Full precision: the written k_re reads back exactly.
        let line = t.measurements_csv().lines().nth(1).unwrap().to_string();
        let k: f64 = line.split(',').nth(3).unwrap().parse().unwrap();
        assert_eq!(k, net[0].measurements[0].k_re);
    }

    #[test]
    fn truth_round_trips_through_the_file() {
        let net = generate(&SynthOptions {
            segments: 4,
            seed: 9,
            defect_fraction: 0.5,
            ..Default::default()
        });
        let mut t = NetworkTables::from_synth(&net, 27700);
        t.push_published(published::lu2022().unwrap());
        let dir = std::env::temp_dir().join(format!(
            "pipewave-truth-test-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        t.write_dir(&dir).unwrap();
        let back = read_truth(&dir.join(TRUTH_CSV)).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back, t.truth);
        assert_eq!(back[4].soil_youngs_modulus_pa, None);
        assert!(back[4].source.starts_with("published: Lu"));
    }

    #[test]
    fn text_cells_are_quoted_when_needed() {
        let body = csv_text(
            vec!["a", "b", "c"],
            [vec!["x,y".to_string(), "say \"x\"".into(), "plain".into()]],
        );
        assert_eq!(body, "a,b,c\n\"x,y\",\"say \"\"x\"\"\",plain\n");
    }
}
