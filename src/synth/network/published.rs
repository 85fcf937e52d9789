//! The two published field measurements of buried water pipes, as segments of a network
//! (`pipewave synth` appends them; `sample_network/real/` holds a copy of the source files).
//!
//! The data and their provenance are described in `tests/data/published/README.md`; the CSV
//! files are embedded here unchanged.
//!
//! * `LU2022-CI-DN125`: Lu, Chen, Sheng, Gao, Sensors 22 (2022) 3942, Table 2: four wavenumbers
//!   of a cast-iron main, with the paper's Table 1 pipe and soil density. The pipe size is not
//!   published: DN125 (OD 144 mm, 6 mm wall) is pipewave's inference (see the data README).
//! * `MUGGLETON2004-MDPE`: Muggleton, Brennan, Linford, J. Sound Vib. 270 (2004) 171–190, the
//!   buried MDPE pipe. Its 326 raw rows from 100 Hz up to (not including) 750 Hz are averaged in
//!   50 Hz bands; the pipe and soil density are those identified from the group's model curves.

use super::TruthRow;
use crate::db::{MeasurementRecord, SegmentRecord};
use crate::physics::Material;
use crate::units::db_to_np;

/// The paper's Table 2, as in `tests/data/published/seed_cast_iron_table2.csv`.
pub const LU2022_CSV: &str =
    include_str!("../../../tests/data/published/seed_cast_iron_table2.csv");
/// The Muggleton et al. (2004) series, as in
/// `tests/data/published/muggleton2004_buried_mdpe.csv`.
pub const MUGGLETON2004_CSV: &str =
    include_str!("../../../tests/data/published/muggleton2004_buried_mdpe.csv");
/// The README describing both files.
pub const README_MD: &str = include_str!("../../../tests/data/published/README.md");

/// Segment id of the cast-iron main of Lu et al. (2022).
pub const LU2022_ID: &str = "LU2022-CI-DN125";
/// Segment id of the buried MDPE pipe of Muggleton et al. (2004).
pub const MUGGLETON2004_ID: &str = "MUGGLETON2004-MDPE";

/// Lower edge of the first band of the MDPE series, Hz: below it the raw estimates are
/// unreliable (data README).
pub const MUGGLETON_BAND_START_HZ: f64 = 100.0;
/// Upper edge (excluded) of the last band, Hz: above it the raw estimates are unreliable.
pub const MUGGLETON_BAND_END_HZ: f64 = 750.0;
/// Width of one averaging band, Hz.
pub const MUGGLETON_BAND_WIDTH_HZ: f64 = 50.0;

/// A published case as one segment of a network.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedCase {
    /// The inventory record, with its measurements.
    pub segment: SegmentRecord,
    /// Its truth row: the soil is not known, so only the source is filled in.
    pub truth: TruthRow,
}

impl PublishedCase {
    /// What a fit is given about this case: water, the pipe from the material and the row's
    /// overrides (a = (D_o − h)/2, eq. P6), the soil density and the measurements.
    pub fn segment_data(&self) -> Result<crate::invert::SegmentData, crate::physics::InputError> {
        crate::rows::segment_data(&self.segment)
    }
}

/// The inventory record of a published case: no geometry, no soil description, water.
#[allow(clippy::too_many_arguments)]
fn published_record(
    segment_id: &str,
    material: Material,
    outer_diameter_mm: f64,
    wall_thickness_mm: f64,
    soil_density_kg_m3: f64,
    pipe: crate::physics::MaterialProps,
    measurements: Vec<MeasurementRecord>,
) -> SegmentRecord {
    SegmentRecord {
        pipe_youngs_modulus_pa: Some(pipe.youngs_modulus),
        pipe_poisson: Some(pipe.poisson),
        pipe_density_kg_m3: Some(pipe.density),
        pipe_loss_factor: Some(pipe.loss_factor),
        measurements,
        ..SegmentRecord::new(
            segment_id,
            material,
            outer_diameter_mm,
            wall_thickness_mm,
            soil_density_kg_m3,
        )
    }
}

/// A problem with an embedded data file (only possible if the files in `tests/data/published/`
/// are edited into an unreadable form).
#[derive(Debug, thiserror::Error)]
#[error("published data {file}, line {line}: {message}")]
pub struct PublishedDataError {
    /// The file.
    pub file: &'static str,
    /// 1-based line.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// Rows of a small numeric CSV: the header and the values, every cell a number.
fn numeric_rows(
    file: &'static str,
    text: &str,
) -> Result<(Vec<String>, Vec<Vec<f64>>), PublishedDataError> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or(PublishedDataError {
        file,
        line: 1,
        message: "empty file".into(),
    })?;
    let header: Vec<String> = header.split(',').map(|s| s.trim().to_string()).collect();
    let mut rows = Vec::new();
    for (i, line) in lines {
        let row = line
            .split(',')
            .map(|c| c.trim().parse::<f64>())
            .collect::<Result<Vec<f64>, _>>()
            .map_err(|e| PublishedDataError {
                file,
                line: i + 1,
                message: format!("not a number: {e}"),
            })?;
        if row.len() != header.len() {
            return Err(PublishedDataError {
                file,
                line: i + 1,
                message: format!("{} cells, expected {}", row.len(), header.len()),
            });
        }
        rows.push(row);
    }
    Ok((header, rows))
}

/// The column index of `name`.
fn column(file: &'static str, header: &[String], name: &str) -> Result<usize, PublishedDataError> {
    header
        .iter()
        .position(|h| h == name)
        .ok_or_else(|| PublishedDataError {
            file,
            line: 1,
            message: format!("no column {name}"),
        })
}

/// Both cases, cast iron first.
pub fn published_cases() -> Result<Vec<PublishedCase>, PublishedDataError> {
    Ok(vec![lu2022()?, muggleton2004()?])
}

/// The cast-iron main of Lu et al. (2022): Table 1 pipe (E 1.22e11 Pa, ν 0.25, ρ 7800 kg/m³,
/// η 0.01) with the inferred DN125 size, soil density 1999 kg/m³ from the soil test, and the
/// four Table 2 rows at their angular frequencies (no standard deviations are published).
pub fn lu2022() -> Result<PublishedCase, PublishedDataError> {
    const FILE: &str = "seed_cast_iron_table2.csv";
    let (header, rows) = numeric_rows(FILE, LU2022_CSV)?;
    let (w, k, a) = (
        column(FILE, &header, "omega_rad_s")?,
        column(FILE, &header, "k_re_rad_per_m")?,
        column(FILE, &header, "attenuation_np_per_m")?,
    );
    let measurements = rows
        .iter()
        .map(|r| MeasurementRecord {
            omega_rad_s: r[w],
            frequency_hz: r[w] / std::f64::consts::TAU,
            k_re_rad_per_m: r[k],
            attenuation_np_per_m: r[a],
            k_re_std: None,
            attenuation_std: None,
            measured_on: None,
            campaign: Some("lu2022_table2".into()),
            note: None,
        })
        .collect();
    Ok(PublishedCase {
        segment: published_record(
            LU2022_ID,
            Material::CastIron,
            144.0,
            6.0,
            1999.0,
            crate::physics::MaterialProps {
                youngs_modulus: 1.22e11,
                poisson: 0.25,
                density: 7800.0,
                loss_factor: 0.01,
            },
            measurements,
        ),
        truth: TruthRow::unknown(LU2022_ID, "published: Lu et al. 2022, Sensors 22(10) 3942"),
    })
}

/// One averaging band of the MDPE series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// Lower edge, Hz (included).
    pub lower_hz: f64,
    /// Upper edge, Hz (excluded).
    pub upper_hz: f64,
    /// Raw rows in the band.
    pub rows: usize,
    /// Mean frequency of the rows, Hz.
    pub frequency_hz: f64,
    /// Mean Re k, rad/m.
    pub k_re: f64,
    /// Standard deviation of that mean (sample standard deviation / √n), rad/m.
    pub k_re_std: f64,
    /// Mean attenuation, Np/m.
    pub attenuation_np: f64,
    /// Standard deviation of that mean, Np/m.
    pub attenuation_std: f64,
}

/// Mean and standard deviation of the mean (n − 1 in the variance).
fn mean_and_sem(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, f64::NAN);
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// The MDPE series averaged in 50 Hz bands [100, 150), [150, 200), …, [700, 750): per band the
/// mean frequency, the mean Re k and the mean attenuation (dB/m converted to Np/m), each with
/// the standard deviation of the mean from the scatter of the rows. The scatter includes the
/// rise of Re k across the band, so these are generous (about 1 % of Re k) rather than tight.
pub fn muggleton2004_bands() -> Result<Vec<Band>, PublishedDataError> {
    const FILE: &str = "muggleton2004_buried_mdpe.csv";
    let (header, rows) = numeric_rows(FILE, MUGGLETON2004_CSV)?;
    let (f, k, a) = (
        column(FILE, &header, "frequency_hz")?,
        column(FILE, &header, "k_re_rad_per_m")?,
        column(FILE, &header, "attenuation_db_per_m")?,
    );
    let n_bands = ((MUGGLETON_BAND_END_HZ - MUGGLETON_BAND_START_HZ) / MUGGLETON_BAND_WIDTH_HZ)
        .round() as usize;
    let mut bands = Vec::with_capacity(n_bands);
    for b in 0..n_bands {
        let lower = MUGGLETON_BAND_START_HZ + MUGGLETON_BAND_WIDTH_HZ * b as f64;
        let upper = lower + MUGGLETON_BAND_WIDTH_HZ;
        let inside: Vec<&Vec<f64>> = rows
            .iter()
            .filter(|r| r[f] >= lower && r[f] < upper)
            .collect();
        if inside.len() < 2 {
            return Err(PublishedDataError {
                file: FILE,
                line: 0,
                message: format!("fewer than 2 rows in the band {lower}-{upper} Hz"),
            });
        }
        let col = |c: usize| inside.iter().map(|r| r[c]).collect::<Vec<f64>>();
        let (freq, _) = mean_and_sem(&col(f));
        let (k_re, k_re_std) = mean_and_sem(&col(k));
        let (att_db, att_db_std) = mean_and_sem(&col(a));
        bands.push(Band {
            lower_hz: lower,
            upper_hz: upper,
            rows: inside.len(),
            frequency_hz: freq,
            k_re,
            k_re_std,
            attenuation_np: db_to_np(att_db),
            attenuation_std: db_to_np(att_db_std),
        });
    }
    Ok(bands)
}

/// The buried MDPE pipe of Muggleton et al. (2004): MDPE with E 2.0e9 Pa, ν 0.4, ρ 900 kg/m³,
/// η 0.06 (the group's "low temperature" curves), mean radius 84.5 mm and wall 11 mm, i.e.
/// OD 2·84.5 + 11 = 180 mm, soil density 1500 kg/m³, and the 13 band averages of
/// [`muggleton2004_bands`].
pub fn muggleton2004() -> Result<PublishedCase, PublishedDataError> {
    let measurements = muggleton2004_bands()?
        .iter()
        .map(|b| MeasurementRecord {
            omega_rad_s: crate::units::hz_to_omega(b.frequency_hz),
            frequency_hz: b.frequency_hz,
            k_re_rad_per_m: b.k_re,
            attenuation_np_per_m: b.attenuation_np,
            k_re_std: Some(b.k_re_std),
            attenuation_std: Some(b.attenuation_std),
            measured_on: None,
            campaign: Some("muggleton2004_50hz_bands".into()),
            note: None,
        })
        .collect();
    Ok(PublishedCase {
        segment: published_record(
            MUGGLETON2004_ID,
            Material::Mdpe,
            2.0 * 84.5 + 11.0,
            11.0,
            1500.0,
            crate::physics::MaterialProps {
                youngs_modulus: 2.0e9,
                poisson: 0.4,
                density: 900.0,
                loss_factor: 0.06,
            },
            measurements,
        ),
        truth: TruthRow::unknown(
            MUGGLETON2004_ID,
            "published: Muggleton et al. 2004, J. Sound Vib. 270 171-190",
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lu2022_has_the_four_table2_rows() {
        let c = lu2022().unwrap();
        assert_eq!(c.segment.measurements.len(), 4);
        assert_eq!(c.segment.measurements[0].omega_rad_s, 3121.958);
        assert_eq!(c.segment.measurements[3].k_re_rad_per_m, 8.16);
        assert_eq!(c.segment.measurements[3].attenuation_np_per_m, 0.0596);
        assert!(c.segment.measurements.iter().all(|m| m.k_re_std.is_none()));
        assert_eq!(c.segment.outer_diameter_mm, 144.0);
    }

    /// The data README: 326 rows from 100 Hz to below 750 Hz (one frequency, 300 Hz, appears
    /// twice), 25 per band but 26 in the 300-350 Hz band.
    #[test]
    fn muggleton_bands_cover_the_326_usable_rows() {
        let bands = muggleton2004_bands().unwrap();
        assert_eq!(bands.len(), 13);
        assert_eq!(bands.iter().map(|b| b.rows).sum::<usize>(), 326);
        assert_eq!(bands[4].rows, 26);
        assert_eq!((bands[0].lower_hz, bands[12].upper_hz), (100.0, 750.0));
        // First band: rows 100, 102, ..., 148 Hz.
        assert!((bands[0].frequency_hz - 124.0).abs() < 1e-12);
        for b in &bands {
            assert!(b.k_re_std > 0.0 && b.k_re_std < 0.03 * b.k_re, "{b:?}");
            assert!(b.attenuation_np > 0.0 && b.attenuation_std > 0.0, "{b:?}");
        }
        // Re k rises with frequency (a 360 m/s wave: k ≈ 2πf/360).
        assert!(bands.windows(2).all(|w| w[1].k_re > w[0].k_re));
        let c = muggleton2004().unwrap();
        assert_eq!(c.segment.outer_diameter_mm, 180.0);
        assert_eq!(c.segment.measurements.len(), 13);
    }

    /// Independent check of one band against a hand computation from the raw file.
    #[test]
    fn muggleton_band_means_match_a_direct_average() {
        let (header, rows) = numeric_rows("m", MUGGLETON2004_CSV).unwrap();
        assert_eq!(header[2], "attenuation_db_per_m");
        let inside: Vec<&Vec<f64>> = rows
            .iter()
            .filter(|r| (500.0..550.0).contains(&r[0]))
            .collect();
        assert_eq!(inside.len(), 25);
        let k: f64 = inside.iter().map(|r| r[1]).sum::<f64>() / 25.0;
        let a: f64 = inside.iter().map(|r| r[2]).sum::<f64>() / 25.0 / 8.685889638065035;
        let b = muggleton2004_bands().unwrap()[8];
        assert_eq!(b.lower_hz, 500.0);
        assert!((b.k_re - k).abs() < 1e-12 * k);
        assert!((b.attenuation_np - a).abs() < 1e-12 * a);
    }

    #[test]
    fn mean_and_sem_of_known_values() {
        let (m, s) = mean_and_sem(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        // Sample variance 5/3, standard error sqrt(5/3/4).
        assert!((s - (5.0_f64 / 12.0).sqrt()).abs() < 1e-15);
    }
}
