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

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::physics::Material;
use crate::synth::SynthSegment;

/// File names inside a network directory.
pub const SEGMENTS_CSV: &str = "segments.csv";
/// Field wavenumbers.
pub const MEASUREMENTS_CSV: &str = "measurements.csv";
/// The truth of a synthetic network.
pub const TRUTH_CSV: &str = "truth.csv";

/// The `source` of a synthetic segment in `truth.csv`.
pub const SOURCE_SYNTHETIC: &str = "synthetic";

/// One row of `segments.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct InventoryRow {
    /// Asset id.
    pub segment_id: String,
    /// Material.
    pub material: Material,
    /// Outside diameter, mm.
    pub outer_diameter_mm: f64,
    /// Wall thickness, mm.
    pub wall_thickness_mm: f64,
    /// Soil density, kg/m³.
    pub soil_density_kg_m3: f64,
    /// Override of the material's Young's modulus, Pa.
    pub pipe_youngs_modulus_pa: Option<f64>,
    /// Override of the material's Poisson's ratio.
    pub pipe_poisson: Option<f64>,
    /// Override of the material's density, kg/m³.
    pub pipe_density_kg_m3: Option<f64>,
    /// Override of the material's loss factor.
    pub pipe_loss_factor: Option<f64>,
    /// Length, m.
    pub length_m: Option<f64>,
    /// Soil description.
    pub soil_type: Option<String>,
    /// Year laid.
    pub install_year: Option<u32>,
    /// Polyline vertices in EPSG:`srid` (empty: no geometry).
    pub geometry: Vec<(f64, f64)>,
    /// EPSG code of the geometry.
    pub srid: Option<u32>,
    /// Soil zone (physics §7.11); the column is written only when some segment has one.
    pub soil_zone: Option<String>,
}

/// One row of `measurements.csv`: exactly one of `frequency_hz` / `omega_rad_s` is set.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementRow {
    /// Segment.
    pub segment_id: String,
    /// Frequency, Hz.
    pub frequency_hz: Option<f64>,
    /// Angular frequency, rad/s.
    pub omega_rad_s: Option<f64>,
    /// Re k, rad/m.
    pub k_re_rad_per_m: f64,
    /// Attenuation, Np/m (positive).
    pub attenuation_np_per_m: f64,
    /// One sigma of Re k, rad/m.
    pub k_re_std: Option<f64>,
    /// One sigma of the attenuation, Np/m.
    pub attenuation_std: Option<f64>,
    /// Campaign name.
    pub campaign: Option<String>,
}

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
        }
    }
}

/// The three tables of a network directory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NetworkTables {
    /// `segments.csv`.
    pub segments: Vec<InventoryRow>,
    /// `measurements.csv`.
    pub measurements: Vec<MeasurementRow>,
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
    /// properties (no overrides), as [`crate::synth::generate`] does.
    pub fn from_synth(segments: &[SynthSegment], srid: u32) -> NetworkTables {
        let mut t = NetworkTables::default();
        for s in segments {
            t.segments.push(InventoryRow {
                segment_id: s.id.clone(),
                material: s.material,
                outer_diameter_mm: s.size.od_mm,
                wall_thickness_mm: s.size.wall_mm,
                soil_density_kg_m3: s.soil_density,
                pipe_youngs_modulus_pa: None,
                pipe_poisson: None,
                pipe_density_kg_m3: None,
                pipe_loss_factor: None,
                length_m: Some(round_to(s.length_m, 2)),
                soil_type: Some(s.soil_type.to_string()),
                install_year: Some(s.install_year),
                geometry: s
                    .geometry
                    .iter()
                    .map(|&(x, y)| (round_to(x, 2), round_to(y, 2)))
                    .collect(),
                srid: (!s.geometry.is_empty()).then_some(srid),
                soil_zone: s.soil_zone.clone(),
            });
            for m in &s.measurements {
                t.measurements.push(MeasurementRow {
                    segment_id: s.id.clone(),
                    frequency_hz: Some(m.frequency_hz),
                    omega_rad_s: None,
                    k_re_rad_per_m: m.k_re,
                    attenuation_np_per_m: m.attenuation,
                    k_re_std: Some(m.k_re_std),
                    attenuation_std: Some(m.attenuation_std),
                    campaign: Some("synthetic".into()),
                });
            }
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
            });
        }
        t
    }

    /// Append a published case.
    pub fn push_published(&mut self, case: published::PublishedCase) {
        self.segments.push(case.segment);
        self.measurements.extend(case.measurements);
        self.truth.push(case.truth);
    }

    /// `segments.csv` as text.
    pub fn segments_csv(&self) -> String {
        let mut out = String::from(
            "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,\
             pipe_youngs_modulus_pa,pipe_poisson,pipe_density_kg_m3,pipe_loss_factor,length_m,\
             soil_type,install_year,geometry_wkt,srid",
        );
        let zoned = self.segments.iter().any(|s| s.soil_zone.is_some());
        out.push_str(if zoned { ",soil_zone\n" } else { "\n" });
        for s in &self.segments {
            let geometry = if s.geometry.is_empty() {
                String::new()
            } else {
                let pts: Vec<String> = s.geometry.iter().map(|(x, y)| format!("{x} {y}")).collect();
                // Quoted: the WKT contains commas.
                format!("\"LINESTRING ({})\"", pts.join(", "))
            };
            let _ = write!(
                out,
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                text(&s.segment_id),
                s.material.code(),
                s.outer_diameter_mm,
                s.wall_thickness_mm,
                s.soil_density_kg_m3,
                opt(s.pipe_youngs_modulus_pa),
                opt(s.pipe_poisson),
                opt(s.pipe_density_kg_m3),
                opt(s.pipe_loss_factor),
                opt(s.length_m),
                s.soil_type.as_deref().map(text).unwrap_or_default(),
                s.install_year.map(|y| y.to_string()).unwrap_or_default(),
                geometry,
                s.srid.map(|v| v.to_string()).unwrap_or_default(),
            );
            if zoned {
                out.push(',');
                out.push_str(&s.soil_zone.as_deref().map(text).unwrap_or_default());
            }
            out.push('\n');
        }
        out
    }

    /// `measurements.csv` as text.
    pub fn measurements_csv(&self) -> String {
        let mut out = String::from(
            "segment_id,frequency_hz,omega_rad_s,k_re_rad_per_m,attenuation_np_per_m,k_re_std,\
             attenuation_std,campaign\n",
        );
        for m in &self.measurements {
            let _ = writeln!(
                out,
                "{},{},{},{},{},{},{},{}",
                text(&m.segment_id),
                opt(m.frequency_hz),
                opt(m.omega_rad_s),
                m.k_re_rad_per_m,
                m.attenuation_np_per_m,
                opt(m.k_re_std),
                opt(m.attenuation_std),
                m.campaign.as_deref().map(text).unwrap_or_default(),
            );
        }
        out
    }

    /// `truth.csv` as text.
    pub fn truth_csv(&self) -> String {
        let mut out = String::from(
            "segment_id,source,soil_type,soil_youngs_modulus_pa,soil_poisson,contact,\
             hidden_effect,hidden_effect_value,defect",
        );
        let zoned = self.truth.iter().any(|t| t.soil_zone.is_some());
        out.push_str(if zoned {
            ",soil_zone,zone_soil_youngs_modulus_pa,zone_soil_poisson\n"
        } else {
            "\n"
        });
        for t in &self.truth {
            let _ = write!(
                out,
                "{},{},{},{},{},{},{},{},{}",
                text(&t.segment_id),
                text(&t.source),
                t.soil_type.as_deref().map(text).unwrap_or_default(),
                opt(t.soil_youngs_modulus_pa),
                opt(t.soil_poisson),
                opt(t.contact),
                t.hidden_effect.as_deref().map(text).unwrap_or_default(),
                opt(t.hidden_effect_value),
                t.defect.as_deref().map(text).unwrap_or_default(),
            );
            if zoned {
                let _ = write!(
                    out,
                    ",{},{},{}",
                    t.soil_zone.as_deref().map(text).unwrap_or_default(),
                    opt(t.zone_soil_youngs_modulus_pa),
                    opt(t.zone_soil_poisson),
                );
            }
            out.push('\n');
        }
        out
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
            std::fs::write(&path, body).map_err(|source| NetworkError::Io {
                action: "write",
                path,
                source,
            })?;
        }
        Ok(())
    }
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

/// A text cell, quoted when it holds a comma, quote or line break.
fn text(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
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
            t.measurements.len(),
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
        assert_eq!(text("a,b"), "\"a,b\"");
        assert_eq!(text("say \"x\""), "\"say \"\"x\"\"\"");
        assert_eq!(text("plain"), "plain");
    }
}
