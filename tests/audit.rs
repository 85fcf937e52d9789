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
    for attr in ["src=", "@import", "url("] {
        assert!(!html.contains(attr), "{attr} in the page");
    }
    // Links only within the page.
    for (i, _) in html.match_indices("href=") {
        assert!(html[i..].starts_with("href=\"#"), "{}", &html[i..i + 40]);
    }
    // Escaped user text.
    assert!(html.contains("A&amp;B&lt;1&gt;"));
    assert!(!html.contains("A&B<1>"));

    let svgs = svgs(&html);
    // status bars, two maps, soil-speed chart, histogram, scatter, two per worst fit.
    let fitted = (0..N)
        .filter(|&i| !fx::is_unfitted(i) && !fx::is_failed(i))
        .count();
    let worst = fitted.min(report::audit::WORST_FITS);
    assert!(svgs.len() >= 4 + 4 + 2 * worst, "{} svgs", svgs.len());
    for s in &svgs {
        parse_xml(s);
    }
    // The maps (speed, relative error): one path per segment with a geometry, each with its
    // id as tooltip (and the casings of distrusted segments, the legend's line samples and
    // the scale bar, without one).
    let maps: Vec<&&str> = svgs
        .iter()
        .filter(|s| s.contains("class=\"map\""))
        .collect();
    assert_eq!(maps.len(), 2);
    let with_geometry = (0..N).filter(|&i| fx::has_geometry(i)).count() + 1;
    for map in &maps {
        let names = parse_xml(map);
        assert!(
            names.get("path").is_some_and(|&n| n > with_geometry),
            "{names:?}"
        );
        assert_eq!(names.get("title"), Some(&with_geometry));
        assert_eq!(map.matches("\"><title>").count(), with_geometry);
    }
    // S00000 is fitted ok with a stored speed error.
    assert!(maps[0].contains("<title>S00000: ") && maps[0].contains(" m/s (ok)</title>"));
    assert!(maps[1].contains("<title>S00000: ") && maps[1].contains(" % of the speed</title>"));
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

/// The lead sections against the database: counts of ok fits, flags and notes; the
/// least-certain table sorted by relative error; the soil types of the c_P figure and their
/// weighted means; escaped ids and soil types.
#[test]
fn lead_sections_match_the_database() {
    use pipewave::db::{CurvePoint, FitRow, FitStatus};
    use pipewave::invert::FlagCode;
    use pipewave::physics::curves::STANDARD_GRID_HZ;
    use pipewave::physics::{ContactMode, Model};
    use pipewave::report::svg::escape;
    use report_check::{section, table_rows};
    use std::collections::BTreeMap;

    let dir = tempfile::tempdir().unwrap();
    let mut database = fx::build(&dir.path().join("pipewave.sqlite"), N);
    // A segment whose id and soil type need escaping, fitted with a very uncertain speed.
    let nasty_id = "A&B<1>";
    let nasty_soil = "<b>peat</b> & \"fill\"";
    let r = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes(
            "segments.csv",
            "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,soil_type,geometry_wkt,srid\n\
             \"A&B<1>\",PVC,110,5,1800,\"<b>peat</b> & \"\"fill\"\"\",\"LINESTRING (441800 111900, 441850 111920)\",27700\n",
        )),
        None,
        ImportOptions::default(),
    )
    .unwrap();
    assert!(r.errors.is_empty(), "{:?}", r.errors);
    let run_id = db::latest_fits(database.conn(), None).unwrap()[0].run_id;
    let mut fit = FitRow::new(
        nasty_id,
        run_id,
        FitStatus::Flagged,
        Model::Full,
        ContactMode::Reciprocal,
    );
    fit.flags = "speed_uncertain".into();
    fit.soil_p_wave_speed_m_per_s = Some(150.0);
    fit.soil_p_wave_speed_std_m_per_s = Some(6.0);
    fit.leak_band_speed_m_per_s = Some(300.0);
    fit.leak_band_speed_std_m_per_s = Some(150.0);
    let curve: Vec<CurvePoint> = STANDARD_GRID_HZ
        .iter()
        .map(|&f| CurvePoint {
            frequency_hz: f,
            phase_speed_m_per_s: Some(300.0),
            attenuation_db_per_m: Some(0.01),
            phase_speed_std_m_per_s: Some(150.0),
            attenuation_std_db_per_m: Some(0.001),
            model_phase_speed_m_per_s: None,
            model_attenuation_db_per_m: None,
        })
        .collect();
    db::insert_fit_with_curves(database.conn_mut(), &fit, &curve).unwrap();

    let out = dir.path().join("report.html");
    report::audit::write(&database, &out).unwrap();
    let html = std::fs::read_to_string(&out).unwrap();
    // The lead sections come first, in order.
    let pos: Vec<usize> = SECTIONS
        .iter()
        .map(|s| html.find(&format!("<section id=\"{s}\">")).unwrap())
        .collect();
    assert!(pos.windows(2).all(|w| w[0] < w[1]), "sections out of order");

    let fits = db::latest_fits(database.conn(), None).unwrap();
    let segments = db::load_segments(database.conn(), None).unwrap();
    let soil_of: BTreeMap<&str, &str> = segments
        .iter()
        .map(|s| (s.segment_id.as_str(), s.soil_type.as_deref().unwrap_or("")))
        .collect();
    let non_failed: Vec<&FitRow> = fits
        .iter()
        .filter(|f| f.status != FitStatus::Failed)
        .collect();

    // Trustworthy predictions and the flags to act on, with their advice.
    let trust = section(&html, "trust");
    let ok = fits.iter().filter(|f| f.status == FitStatus::Ok).count();
    assert!(ok > 10);
    assert!(
        trust.contains(&format!("<b>{ok} of {} segments", segments.len())),
        "ok count"
    );
    assert!(trust.contains(&format!("<tr><td>ok</td><td class=\"n\">{ok}</td>")));
    let count = |list: fn(&FitRow) -> &str, code: &str| {
        fits.iter()
            .filter(|f| list(f).split(',').any(|c| c == code))
            .count()
    };
    for code in [FlagCode::HighMisfit, FlagCode::SpeedUncertain] {
        let n = count(|f| f.flags.as_str(), code.as_str());
        assert!(n > 0);
        assert!(
            trust.contains(&format!(
                "<tr><td>{code}</td><td class=\"n\">{n}</td><td>{}</td></tr>",
                escape(code.advice())
            )),
            "flag {code}"
        );
    }
    // Notes: a compact table, each code with its count and meaning, never in the flag table.
    let notes = section(&html, "notes");
    for code in [
        FlagCode::SoilViaCp,
        FlagCode::ContactUndetermined,
        FlagCode::AtBound,
    ] {
        let n = count(|f| f.notes.as_str(), code.as_str());
        assert!(n > 0);
        assert!(
            notes.contains(&format!(
                "<tr><td>{code}</td><td class=\"n\">{n}</td><td>{}</td></tr>",
                escape(code.advice())
            )),
            "note {code}"
        );
    }
    // The fixture stores `at_bound` among some flags (as older pipewave did), never these.
    for code in [FlagCode::SoilViaCp, FlagCode::ContactUndetermined] {
        assert!(!trust.contains(&format!("<tr><td>{code}</td>")));
    }

    // The least certain speeds: sorted by relative error, the escaped segment first.
    let least = section(&html, "least-certain");
    let rows = table_rows(least);
    let with_error = non_failed
        .iter()
        .filter(|f| f.leak_band_speed_std_m_per_s.is_some())
        .count();
    assert_eq!(
        rows.len(),
        with_error.min(report::audit::LEAST_CERTAIN_LISTED)
    );
    let rel: Vec<f64> = rows
        .iter()
        .map(|r| r[4].trim_end_matches(" %").parse::<f64>().unwrap())
        .collect();
    assert!(rel.windows(2).all(|w| w[0] >= w[1]), "not sorted: {rel:?}");
    assert_eq!(rows[0][0], escape(nasty_id));
    assert_eq!(rows[0][2], escape(nasty_soil));
    assert_eq!(rows[0][3], "300 ± 150");
    assert_eq!(rel[0], 50.0);
    // The second row is the fixture's largest relative error.
    let mut fixture_rel: Vec<(f64, &str)> = non_failed
        .iter()
        .filter(|f| f.segment_id != nasty_id)
        .filter_map(|f| {
            Some((
                f.leak_band_speed_std_m_per_s? / f.leak_band_speed_m_per_s?,
                f.segment_id.as_str(),
            ))
        })
        .collect();
    fixture_rel.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(b.1)));
    assert_eq!(rows[1][0], fixture_rel[0].1);
    assert!((rel[1] - 100.0 * fixture_rel[0].0).abs() < 0.006);
    let without = non_failed.len() - with_error;
    assert!(without > 0);
    assert!(least.contains(&format!(
        "{without} fitted segment(s) have a speed but no stored error"
    )));

    // c_P by soil type: every type with a determined c_P named in the figure, with the
    // inverse-variance weighted mean in the table.
    let soil = section(&html, "soil-speeds");
    let mut by_type: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    let mut cs_by_type: BTreeMap<&str, usize> = BTreeMap::new();
    for f in &non_failed {
        let t = soil_of[f.segment_id.as_str()];
        if let (Some(v), Some(s)) = (f.soil_p_wave_speed_m_per_s, f.soil_p_wave_speed_std_m_per_s) {
            if s / v <= 0.1 {
                by_type.entry(t).or_default().push((v, s));
            }
        }
        if let (Some(v), Some(s)) = (f.soil_s_wave_speed_m_per_s, f.soil_s_wave_speed_std_m_per_s) {
            if s / v <= 0.1 {
                *cs_by_type.entry(t).or_default() += 1;
            }
        }
    }
    assert_eq!(by_type.len(), 7, "six fixture soils and the escaped one");
    let chart = svgs(soil)
        .into_iter()
        .max_by_key(|s| s.len())
        .expect("soil chart");
    parse_xml(chart);
    let rows = table_rows(soil);
    for (t, v) in &by_type {
        let n_cs = cs_by_type.get(t).copied().unwrap_or(0);
        assert!(
            chart.contains(&format!("{} (c_P: {}, c_S: {n_cs})", escape(t), v.len())),
            "soil type {t} not in the figure"
        );
        let sw: f64 = v.iter().map(|(_, s)| 1.0 / (s * s)).sum();
        let mean = v.iter().map(|(x, s)| x / (s * s)).sum::<f64>() / sw;
        let row = rows
            .iter()
            .find(|r| r[0] == escape(t))
            .unwrap_or_else(|| panic!("soil type {t} not in the table"));
        assert_eq!(row[2], v.len().to_string());
        assert!(
            row[3].starts_with(&format!("{mean:.0} ± ")),
            "{t}: {} vs {mean}",
            row[3]
        );
    }
    assert!(!html.contains(nasty_soil) && !html.contains(nasty_id));
    for s in svgs(&html) {
        parse_xml(s);
    }
}
