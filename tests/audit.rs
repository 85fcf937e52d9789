//! The audit report's structure: self-contained, every section present, every SVG well-formed
//! XML, text escaped, counts as in the database, aggregation for large networks.

mod export_fixture;
mod report_check;

use export_fixture as fx;
use pipewave::db::{self, ImportOptions, ImportSource};
use pipewave::report;
use report_check::{parse_xml, svgs, SECTIONS};

const N: usize = 80;

#[test]
fn report_has_every_section_and_well_formed_svg() {
    let dir = tempfile::tempdir().unwrap();
    let mut database = fx::build(&dir.path().join("pipewave.sqlite"), N);
    // A segment whose id and soil type need escaping.
    let r = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes(
            "segments.csv",
            "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,soil_type,geometry_wkt,srid\n\
             \"A&B<1>\",PVC,110,5,1800,\"<script>alert('x')</script> & \"\"clay\"\"\",\"LINESTRING (441800 111900, 441850 111920)\",27700\n",
        )),
        None,
        ImportOptions::default(),
    )
    .unwrap();
    assert!(r.errors.is_empty(), "{:?}", r.errors);
    let out = dir.path().join("report.html");
    let summary = report::audit::write(&database, &out).unwrap();
    assert_eq!(summary.segments, N + 1);
    let html = std::fs::read_to_string(&out).unwrap();

    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.trim_end().ends_with("</html>"));
    for s in SECTIONS {
        assert!(
            html.contains(&format!("<section id=\"{s}\">")),
            "section {s} missing"
        );
    }
    // Self-contained: no script, no external resource; the only URLs are SVG namespaces.
    assert!(
        !html.to_lowercase().contains("<script"),
        "a script (or unescaped text) is in the page"
    );
    for (i, _) in html.match_indices("http") {
        assert!(
            html[i..].starts_with("http://www.w3.org/2000/svg"),
            "external reference: {}",
            &html[i..i + 60]
        );
    }
    for attr in ["src=", "href=", "@import", "url("] {
        assert!(!html.contains(attr), "{attr} in the page");
    }
    // Escaped user text.
    assert!(html.contains("A&amp;B&lt;1&gt;"));
    assert!(!html.contains("A&B<1>"));

    let svgs = svgs(&html);
    // status/flag bars, map, histogram, scatter, box plot, two per worst fit.
    let fitted = (0..N)
        .filter(|&i| !fx::is_unfitted(i) && !fx::is_failed(i))
        .count();
    let worst = fitted.min(report::audit::WORST_FITS);
    assert!(svgs.len() >= 4 + 4 + 2 * worst, "{} svgs", svgs.len());
    for s in &svgs {
        parse_xml(s);
    }
    // The map: one path per segment with a geometry, each with its id as tooltip.
    let map = svgs
        .iter()
        .find(|s| s.contains("class=\"map\""))
        .expect("map svg");
    let names = parse_xml(map);
    let with_geometry = (0..N).filter(|&i| fx::has_geometry(i)).count() + 1;
    assert_eq!(names.get("path"), Some(&with_geometry));
    assert_eq!(names.get("title"), Some(&with_geometry));
    assert!(map.contains("<title>S00000: "));
    // The worst fits: the cap, each with a speed and an attenuation chart.
    assert_eq!(html.matches("<figure id=\"worst-").count(), worst);
    // Counts by status as in the database.
    let count = |pred: &dyn Fn(usize) -> bool| (0..N).filter(|&i| pred(i)).count();
    let failed = count(&|i| !fx::is_unfitted(i) && fx::is_failed(i));
    let unfitted = count(&fx::is_unfitted) + 1;
    assert!(
        html.contains(&format!("<tr><td>failed</td><td class=\"n\">{failed}</td>")),
        "failed count"
    );
    assert!(
        html.contains(&format!(
            "<tr><td>unfitted</td><td class=\"n\">{unfitted}</td>"
        )),
        "unfitted count"
    );
    let flagged = count(&|i| !fx::is_unfitted(i) && !fx::is_failed(i) && fx::is_flagged(i));
    assert!(
        html.contains(&format!(
            "<tr><td>high_misfit</td><td class=\"n\">{flagged}</td>"
        )),
        "flag count"
    );
    assert!(html.contains(&format!("{failed} segment(s) have no fit")));
}

#[test]
fn report_of_an_empty_database_still_has_every_section() {
    let dir = tempfile::tempdir().unwrap();
    let database = pipewave::db::Database::open(dir.path().join("empty.sqlite")).unwrap();
    let out = dir.path().join("report.html");
    report::audit::write(&database, &out).unwrap();
    let html = std::fs::read_to_string(&out).unwrap();
    for s in SECTIONS {
        assert!(
            html.contains(&format!("<section id=\"{s}\">")),
            "section {s} missing"
        );
    }
    for s in svgs(&html) {
        parse_xml(s);
    }
    assert!(html.contains("No segment has a geometry."));
}
