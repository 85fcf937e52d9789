//! A utility's own data, imported with nothing but `pipewave import --help` and
//! docs/your-own-data.md: the help names every column with its unit and the material codes, its
//! example files import as they stand, and a file with the columns in another order, extra
//! columns and the README's material spellings imports and fits.

use std::path::Path;
use std::process::{Command, Output};

use rusqlite::Connection;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("run pipewave")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn long_help() -> String {
    let out = run(&["import", "--help"]);
    assert!(out.status.success());
    text(&out.stdout)
}

/// The indented lines after `heading` up to the next blank line, unindented: an example file.
fn example(help: &str, heading: &str) -> String {
    let start = help
        .find(heading)
        .unwrap_or_else(|| panic!("{heading} missing"));
    help[start + heading.len()..]
        .lines()
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .map(|l| format!("{}\n", l.trim()))
        .collect()
}

#[test]
fn the_long_help_names_columns_units_codes_and_an_example() {
    let help = long_help();
    for column in [
        "segment_id",
        "material",
        "outer_diameter_mm",
        "wall_thickness_mm",
        "soil_density_kg_m3",
        "geometry_wkt",
        "srid",
        "soil_zone",
        "frequency_hz",
        "omega_rad_s",
        "k_re_rad_per_m",
        "attenuation_np_per_m",
        "k_re_std",
        "attenuation_std",
    ] {
        assert!(help.contains(column), "{column} missing from import --help");
    }
    for code in ["CI ", "DI ", "ST ", "PVC", "MDPE", "HDPE", "AC "] {
        assert!(help.contains(code), "material code {code} missing");
    }
    for unit in ["mm", "kg/m3", "Hz", "rad/m", "Np/m"] {
        assert!(help.contains(unit), "unit {unit} missing");
    }
    // The short help stays short and points at the long one.
    let short = text(&run(&["import", "-h"]).stdout);
    assert!(!short.contains("YOUR OWN DATA"));
    assert!(short.contains("pipewave import --help"));
}

#[test]
fn the_help_examples_import_as_they_stand_and_the_docs_show_the_same() {
    let help = long_help();
    let segs = example(&help, "Example segments.csv:");
    let meas = example(&help, "Example measurements.csv:");
    assert_eq!(segs.lines().count(), 2, "{segs}");
    assert_eq!(meas.lines().count(), 3, "{meas}");
    let tmp = tempfile::tempdir().unwrap();
    let (sp, mp) = (tmp.path().join("s.csv"), tmp.path().join("m.csv"));
    std::fs::write(&sp, &segs).unwrap();
    std::fs::write(&mp, &meas).unwrap();
    let db = tmp.path().join("db.sqlite");
    let out = run(&[
        "import",
        "--db",
        s(&db),
        "--segments",
        s(&sp),
        "--measurements",
        s(&mp),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let c = Connection::open(&db).unwrap();
    let m: String = c
        .query_row("SELECT material FROM segments", [], |r| r.get(0))
        .unwrap();
    assert_eq!(m, "DI");
    // The user's document carries the same example rows.
    let doc = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/your-own-data.md"),
    )
    .unwrap();
    for line in segs.lines().chain(meas.lines()) {
        assert!(doc.contains(line), "docs/your-own-data.md lacks: {line}");
    }
}

#[test]
fn columns_in_another_order_extra_columns_and_readme_spellings_import_and_fit() {
    let tmp = tempfile::tempdir().unwrap();
    // Another order, upper-case names, two columns pipewave does not know, and the material
    // spellings the README lists.
    let spellings = [
        ("Cast Iron", "CI"),
        ("Ductile Iron", "DI"),
        ("DICL", "DI"),
        ("Steel", "ST"),
        ("uPVC", "PVC"),
        ("PVC-U", "PVC"),
        ("PE80", "MDPE"),
        ("PE100", "HDPE"),
        ("MDPE", "MDPE"),
        ("HDPE", "HDPE"),
        ("Asbestos Cement", "AC"),
    ];
    let mut segs = String::from(
        "OWNER,Soil_Density_kg_m3,WALL_THICKNESS_MM,segment_id,Material,outer_diameter_mm,\
         inspection_note\n",
    );
    for (i, (spelling, _)) in spellings.iter().enumerate() {
        let plastic = spelling.contains("PE") || spelling.contains("PVC");
        let (od, wall) = if plastic { (125, 11.4) } else { (118, 6.0) };
        segs.push_str(&format!(
            "Water Co,1900,{wall},P-{i:02},{spelling},{od},\"checked, 2019\"\n"
        ));
    }
    // Measurements also reordered, with an extra column; speeds a pipe of either family can
    // have (plastics about 350-500 m/s, metals about 1,100-1,300 m/s at these diameters).
    let mut meas = String::from(
        "attenuation_np_per_m,crew,k_re_rad_per_m,frequency_hz,segment_id,k_re_std,attenuation_std\n",
    );
    for (i, (spelling, _)) in spellings.iter().enumerate() {
        let plastic = spelling.contains("PE") || spelling.contains("PVC");
        let c = if plastic { 420.0 } else { 1200.0 };
        for f in [150.0, 300.0, 450.0] {
            let k = 2.0 * std::f64::consts::PI * f / c;
            meas.push_str(&format!(
                "{:.5},north,{k:.6},{f},P-{i:02},{:.6},{:.6}\n",
                if plastic { 0.02 } else { 0.004 },
                0.01 * k,
                if plastic { 0.002 } else { 0.0004 },
            ));
        }
    }
    let (sp, mp) = (tmp.path().join("segments.csv"), tmp.path().join("meas.csv"));
    std::fs::write(&sp, segs).unwrap();
    std::fs::write(&mp, meas).unwrap();
    let db = tmp.path().join("own.sqlite");
    let out = run(&[
        "import",
        "--db",
        s(&db),
        "--segments",
        s(&sp),
        "--measurements",
        s(&mp),
    ]);
    let err = text(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("OWNER") && err.contains("inspection_note") && err.contains("crew"),
        "the ignored columns are named: {err}"
    );
    let c = Connection::open(&db).unwrap();
    for (i, (spelling, code)) in spellings.iter().enumerate() {
        let m: String = c
            .query_row(
                "SELECT material FROM segments WHERE segment_id = ?1",
                [format!("P-{i:02}")],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(&m, code, "{spelling}");
    }
    let n: i64 = c
        .query_row("SELECT count(*) FROM measurements", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 3 * spellings.len() as i64);
    // They fit: every segment gets a fit (none fails on its inputs).
    let cal = run(&[
        "calibrate",
        "--db",
        s(&db),
        "--jobs",
        "1",
        "--segment",
        "P-00",
        "--segment",
        "P-06",
    ]);
    assert!(cal.status.success(), "{}", text(&cal.stderr));
    assert!(
        text(&cal.stdout).starts_with("calibrate: 2 fitted"),
        "{}",
        text(&cal.stdout)
    );
}

#[test]
fn run_does_not_suggest_skip_invalid_for_a_missing_column() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("net");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(
        dir.join("segments.csv"),
        "segment_id,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\nA,118,6,1900\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("measurements.csv"),
        "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m\nA,200,1.0,0.002\n",
    )
    .unwrap();
    let out = run(&["run", s(&dir)]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.contains("material"), "{err}");
    assert!(
        err.contains("--skip-invalid does not help"),
        "the hint matches import's: {err}"
    );
    assert!(!err.contains("import the valid rows"), "{err}");
}

/// `run DIR --skip-invalid` imports the valid rows of a network directory, lists the bad row by
/// file, line and column, and goes on to calibrate, export and audit; without it `run` imports
/// nothing and says how to go on.
#[test]
fn run_skips_invalid_rows_when_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("net");
    std::fs::create_dir_all(&dir).unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network");
    // The first 12 segments and their measurements, one measurement row made bad.
    let segs = std::fs::read_to_string(src.join("segments.csv")).unwrap();
    let segs: Vec<&str> = segs.lines().take(13).collect();
    std::fs::write(dir.join("segments.csv"), segs.join("\n") + "\n").unwrap();
    let ids: Vec<&str> = segs[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap())
        .collect();
    let meas = std::fs::read_to_string(src.join("measurements.csv")).unwrap();
    let mut lines: Vec<String> = meas
        .lines()
        .enumerate()
        .filter(|(i, l)| *i == 0 || ids.contains(&l.split(',').next().unwrap()))
        .map(|(_, l)| l.to_string())
        .collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = header.iter().position(|h| *h == "k_re_rad_per_m").unwrap();
    let mut bad: Vec<String> = lines[3].split(',').map(str::to_string).collect();
    bad[col] = "fast".to_string();
    lines[3] = bad.join(",");
    let n_rows = lines.len() - 1;
    std::fs::write(dir.join("measurements.csv"), lines.join("\n") + "\n").unwrap();

    let refused = run(&["run", s(&dir)]);
    assert_eq!(refused.status.code(), Some(2));
    let err = text(&refused.stderr);
    assert!(
        err.contains(&format!("{}:4:", s(&dir.join("measurements.csv")))),
        "{err}"
    );
    assert!(err.contains("column k_re_rad_per_m"), "{err}");
    assert!(err.contains("add --skip-invalid"), "{err}");

    let done = run(&["run", s(&dir), "--skip-invalid"]);
    let (out, err) = (text(&done.stdout), text(&done.stderr));
    assert!(done.status.success(), "{out}\n{err}");
    assert!(err.contains("skipped 1 invalid row"), "{err}");
    assert!(
        out.contains(&format!("measurements {} written", n_rows - 1)),
        "{out}"
    );
    assert!(dir.join("out/report.html").is_file());
    let rows = csv::Reader::from_path(dir.join("out/segments.csv"))
        .unwrap()
        .records()
        .count();
    assert_eq!(rows, 12);
}

/// The hints and help texts a new user meets first (issue 64): the empty-file hint gives a
/// header `import` takes (with `frequency_hz`); a pipe too small for the model is reported in
/// the file's own terms (outer diameter and wall in mm), not as a mean radius in m; `import
/// --help` does not send the user to itself for `--db`; `diagnose --help` names groups.csv.
#[test]
fn hints_and_help_speak_the_users_terms() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let segs = d.join("segments.csv");
    std::fs::write(
        &segs,
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n\
         A1,PVC,4.3,0.2,1800\nA2,PVC,110,5.3,1800\n",
    )
    .unwrap();
    let empty = d.join("measurements.csv");
    std::fs::write(&empty, "").unwrap();
    let o = run(&[
        "import",
        "--db",
        s(&d.join("a.sqlite")),
        "--measurements",
        s(&empty),
        "--segments",
        s(&segs),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = text(&o.stderr);
    let hint = err
        .lines()
        .find(|l| l.contains("the file is empty"))
        .unwrap_or_else(|| panic!("{err}"));
    let header = hint.rsplit("such as: ").next().unwrap().trim();
    assert_eq!(
        header,
        "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m"
    );
    // The suggested header imports, with a data row under it.
    std::fs::write(&empty, format!("{header}\nA2,200,0.6,0.001\n")).unwrap();
    let small = err
        .lines()
        .find(|l| l.contains("column outer_diameter_mm"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(small.starts_with(&format!("{}:2:3:", s(&segs))), "{small}");
    assert!(small.contains("outer diameter of 4.3 mm"), "{small}");
    assert!(small.contains("wall of 0.2 mm"), "{small}");
    assert!(
        !small.contains("0.00205") && !small.contains("(m)"),
        "{small}"
    );
    std::fs::write(
        &segs,
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n\
         A2,PVC,110,5.3,1800\n",
    )
    .unwrap();
    let o = run(&[
        "import",
        "--db",
        s(&d.join("b.sqlite")),
        "--segments",
        s(&segs),
        "--measurements",
        s(&empty),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));

    let help = long_help();
    let db_help: String = help
        .lines()
        .skip_while(|l| !l.trim_start().starts_with("--db"))
        .take_while(|l| !l.trim_start().starts_with("--segments"))
        .collect();
    assert!(!db_help.is_empty(), "{help}");
    assert!(!db_help.contains("import --help"), "{db_help}");
    let diag = text(&run(&["diagnose", "--help"]).stdout);
    let out_line = diag
        .lines()
        .find(|l| l.trim_start().starts_with("--out"))
        .unwrap();
    assert!(out_line.contains("groups.csv"), "{out_line}");
}
