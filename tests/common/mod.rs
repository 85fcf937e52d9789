//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod cli;

use std::collections::HashMap;
use std::path::PathBuf;

use num_complex::Complex64;
use pipewave::physics::{ContactMode, Fluid, Model, Pipe, Soil, System};

/// Path of a file under `tests/data/`.
pub fn data_path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

/// A CSV row as a map from column name to text.
pub struct Row(pub HashMap<String, String>);

impl Row {
    pub fn f(&self, k: &str) -> f64 {
        self.0[k]
            .parse()
            .unwrap_or_else(|e| panic!("column {k}: {e}"))
    }
    pub fn s(&self, k: &str) -> &str {
        &self.0[k]
    }
    pub fn c(&self, re: &str, im: &str) -> Complex64 {
        Complex64::new(self.f(re), self.f(im))
    }
}

/// Read a CSV file under `tests/data/` into rows.
pub fn read_csv(rel: &str) -> Vec<Row> {
    let mut rdr = csv::Reader::from_path(data_path(rel)).expect("open csv");
    let headers = rdr.headers().expect("headers").clone();
    rdr.records()
        .map(|r| {
            let r = r.expect("record");
            Row(headers
                .iter()
                .zip(r.iter())
                .map(|(h, v)| (h.to_string(), v.to_string()))
                .collect())
        })
        .collect()
}

/// Relative difference |a − b|/|b| of complex numbers.
pub fn rel(a: Complex64, b: Complex64) -> f64 {
    (a - b).norm() / b.norm()
}

pub fn c(re: f64, im: f64) -> Complex64 {
    Complex64::new(re, im)
}

/// The system described by a row with the `forward` input columns.
pub fn system_from_row(r: &Row) -> System {
    let fluid = Fluid::new(r.f("fluid_density_kg_m3"), r.f("fluid_bulk_modulus_pa")).unwrap();
    let pipe = Pipe::new(
        r.f("pipe_youngs_modulus_pa"),
        r.f("pipe_poisson"),
        r.f("pipe_density_kg_m3"),
        r.f("pipe_loss_factor"),
        r.f("mean_radius_m"),
        r.f("wall_thickness_m"),
    )
    .unwrap();
    let soil = if r.f("soil_youngs_modulus_pa") == 0.0 {
        Soil::none()
    } else {
        Soil::new_unbounded(
            r.f("soil_youngs_modulus_pa"),
            r.f("soil_poisson"),
            r.f("soil_density_kg_m3"),
            r.f("soil_loss_factor"),
        )
        .unwrap()
    };
    System::new(
        fluid,
        pipe,
        soil,
        r.f("contact"),
        r.s("model").parse::<Model>().unwrap(),
        r.s("contact_mode").parse::<ContactMode>().unwrap(),
    )
    .unwrap()
}

/// Spec Appendix A case A, "paper DN125".
pub fn case_a(soil: Soil, contact: f64, model: Model, mode: ContactMode) -> System {
    let pipe = Pipe::new(1.22e11, 0.25, 7800.0, 0.01, 0.069, 0.006).unwrap();
    System::new(Fluid::water(), pipe, soil, contact, model, mode).unwrap()
}

pub fn case_a_soil() -> Soil {
    Soil::new(4.79e7, 0.3326, 1999.0, 0.0).unwrap()
}

/// Spec Appendix A case B, "UK MDPE".
pub fn case_b(soil: Soil, contact: f64, model: Model, mode: ContactMode) -> System {
    let pipe = Pipe::new(2.0e9, 0.4, 900.0, 0.06, 0.0845, 0.011).unwrap();
    System::new(Fluid::water(), pipe, soil, contact, model, mode).unwrap()
}

pub fn case_b_soil() -> Soil {
    Soil::new(4.0e7, 1.0 / 3.0, 1500.0, 0.0).unwrap()
}

/// Spec Appendix A case C, "DN150 DI in loam".
pub fn case_c(soil: Soil, contact: f64, model: Model, mode: ContactMode) -> System {
    let pipe = Pipe::new(1.70e11, 0.28, 7100.0, 0.01, 0.082, 0.006).unwrap();
    System::new(Fluid::water(), pipe, soil, contact, model, mode).unwrap()
}

pub fn case_c_soil() -> Soil {
    Soil::new(5.0e7, 0.35, 1900.0, 0.0).unwrap()
}

/// Case A's four Table 2 angular frequencies, rad/s.
pub const TABLE2_OMEGA: [f64; 4] = [3121.958, 4167.04, 7221.736, 10314.48];
