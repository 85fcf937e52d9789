//! What the lab's generator tests share: reading the written CSV back, and solving a rebuilt
//! pipe's wavenumbers with pipewave's forward model (P13 by continuation).

use std::collections::HashMap;

use num_complex::Complex64;
use pipewave::physics::{solve_curve, Continuation, System};

/// Rows of a CSV text as maps column → cell.
pub fn rows(text: &str) -> Vec<HashMap<String, String>> {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let headers: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            headers
                .iter()
                .cloned()
                .zip(rec.iter().map(String::from))
                .collect()
        })
        .collect()
}

/// A numeric cell of a row.
pub fn num(row: &HashMap<String, String>, col: &str) -> f64 {
    row.get(col)
        .unwrap_or_else(|| panic!("no column {col}"))
        .parse()
        .unwrap_or_else(|e| panic!("{col} = {:?}: {e}", row[col]))
}

/// One measured row: frequency, k_re, α, σ_re, σ_α.
pub type Meas = (f64, f64, f64, f64, f64);

/// The fluid-borne wavenumber k1 of `sys` at each frequency `f` (Hz).
pub fn solve(sys: &System, f: &[f64]) -> Vec<Complex64> {
    let w: Vec<f64> = f.iter().map(|f| 2.0 * std::f64::consts::PI * f).collect();
    solve_curve(sys, &w, Continuation::default())
        .into_iter()
        .map(|r| r.expect("a root").k1)
        .collect()
}

/// FNV-1a 64 of a text (pipewave's own, `db::hash`), for freezing a generator's files.
pub fn fnv1a(text: &str) -> u64 {
    pipewave::db::hash::fnv1a64(text.as_bytes())
}
