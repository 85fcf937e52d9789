//! Size and time of the exports and the audit report for a synthetic network.
//!
//! `cargo run --release --example export_size -- 200 20000`
//!
//! Builds each network in a temporary directory with the test fixture (segments around
//! Southampton in EPSG:27700, five measurements each, fits with curves on the standard grid,
//! written through the database API), then times `export::write` in each format and
//! `report::audit::write`, and prints the file sizes.

#[path = "../tests/export_fixture/mod.rs"]
mod export_fixture;

use std::time::Instant;

use pipewave::export::{self, ExportFormat};
use pipewave::report;

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let sizes = if sizes.is_empty() {
        vec![200, 20_000]
    } else {
        sizes
    };
    println!("segments  output          size (kB)  time (ms)");
    for n in sizes {
        let dir = tempfile::tempdir().expect("temp dir");
        let t = Instant::now();
        let database = export_fixture::build(&dir.path().join("pipewave.sqlite"), n);
        eprintln!(
            "built the {n}-segment fixture in {:.1} s",
            t.elapsed().as_secs_f64()
        );
        for (format, name) in [
            (ExportFormat::Gpkg, "net.gpkg"),
            (ExportFormat::GeoJson, "net.geojson"),
            (ExportFormat::Csv, "net.csv"),
        ] {
            let out = dir.path().join(name);
            let t = Instant::now();
            let s = export::write(&database, format, &out).expect("export");
            let ms = t.elapsed().as_secs_f64() * 1e3;
            assert_eq!(s.segments, n);
            let kb = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0) as f64 / 1024.0;
            println!("{n:>8}  {:<14}  {kb:>9.0}  {ms:>9.0}", format.as_str());
        }
        let out = dir.path().join("report.html");
        let t = Instant::now();
        report::audit::write(&database, &out).expect("audit");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let kb = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0) as f64 / 1024.0;
        println!("{n:>8}  {:<14}  {kb:>9.0}  {ms:>9.0}", "audit html");
        if let Ok(keep) = std::env::var("PIPEWAVE_KEEP_REPORT") {
            let _ = std::fs::copy(&out, format!("{keep}/report-{n}.html"));
        }
    }
}
