//! `pipewave forward` run as a user would: values against the reference roots, error rows.

mod common;

use std::process::Command;

use common::*;

fn pipewave() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

/// The whole of dispersion_roots.csv through the binary (its extra columns are ignored): every
/// root within 1e-10 of the reference, status ok except the two genuine growing waves.
#[test]
fn forward_reproduces_reference_roots() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results.csv");
    let st = pipewave()
        .args(["forward", "--input"])
        .arg(data_path("vectors/dispersion_roots.csv"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let want = read_csv("vectors/dispersion_roots.csv");
    let mut rdr = csv::Reader::from_path(&out).unwrap();
    let got: Vec<csv::StringRecord> = rdr.records().map(|r| r.unwrap()).collect();
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(&g[0], w.s("case_id"));
        let k = c(g[1].parse().unwrap(), g[2].parse().unwrap());
        let e = rel(k, w.c("k_re_rad_per_m", "k_im_np_per_m"));
        assert!(e < 1e-10, "{}: rel {e:e}", &g[0]);
        let speed: f64 = g[3].parse().unwrap();
        assert!((speed / w.f("phase_speed_m_per_s") - 1.0).abs() < 1e-10);
        let att: f64 = g[4].parse().unwrap();
        assert!((att - w.f("attenuation_db_per_m")).abs() <= 1e-10 * att.abs().max(1e-3));
        let expect = if w.f("k_im_np_per_m") > 0.0 {
            "growing_wave"
        } else {
            "ok"
        };
        assert_eq!(&g[5], expect, "{}", &g[0]);
    }
}

const HEADER: &str = "case_id,omega_rad_s,fluid_density_kg_m3,fluid_bulk_modulus_pa,pipe_youngs_modulus_pa,pipe_poisson,pipe_density_kg_m3,pipe_loss_factor,mean_radius_m,wall_thickness_m,soil_youngs_modulus_pa,soil_poisson,soil_density_kg_m3,soil_loss_factor,contact,model,contact_mode";

/// Malformed rows are reported with file, line and column and do not stop the others; a root
/// that is not found gets its reason.
#[test]
fn forward_reports_bad_rows_and_failures() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cases.csv");
    let out = dir.path().join("results.csv");
    let rows = [
        "good,3121.958,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.006,4.79e7,0.3326,1999,0,0,full,reciprocal",
        "text,abc,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.006,4.79e7,0.3326,1999,0,0,full,reciprocal",
        "thick,3121.958,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.03,4.79e7,0.3326,1999,0,0,full,reciprocal",
        "model,3121.958,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.006,4.79e7,0.3326,1999,0,0,exact,reciprocal",
        "nosoil,3121.958,1000,2.25e9,1.22e11,0.25,7800,0.01,0.069,0.006,0,0,0,0,0,seed,blend",
        "lost,4398.23,1000,2.25e9,1.6e9,0.4,900,0.06,0.0845,0.003,1.6e8,0.3333333333333333,1500,0,1,full,reciprocal",
    ];
    std::fs::write(&input, format!("{HEADER}\n{}\n", rows.join("\n"))).unwrap();
    let st = pipewave()
        .args(["forward", "--input"])
        .arg(&input)
        .arg("--output")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(1), "some rows failed");
    let err = String::from_utf8_lossy(&st.stderr);
    let f = input.display().to_string();
    assert!(
        err.contains(&format!("{f}:3:2: column omega_rad_s")),
        "{err}"
    );
    assert!(
        err.contains(&format!("{f}:4:10: column wall_thickness_m")),
        "{err}"
    );
    assert!(err.contains(&format!("{f}:5:16: column model")), "{err}");
    let mut rdr = csv::Reader::from_path(&out).unwrap();
    let got: Vec<csv::StringRecord> = rdr.records().map(|r| r.unwrap()).collect();
    assert_eq!(got.len(), 6, "one output row per input row");
    let status: Vec<&str> = got.iter().map(|r| &r[5]).collect();
    assert_eq!(
        &status[..5],
        &[
            "ok",
            "invalid_input",
            "invalid_input",
            "invalid_input",
            "ok"
        ]
    );
    assert_ne!(
        status[5], "ok",
        "the thin MDPE pipe at 700 Hz leaves the s = 1 branch"
    );
    assert!(
        got[5][1].is_empty(),
        "no number for a root that was not found"
    );
    let k = c(got[0][1].parse().unwrap(), got[0][2].parse().unwrap());
    assert!(rel(k, c(2.487492645359002e+00, -6.190848225577398e-03)) < 1e-10);
    // In vacuo under `blend` is the in-vacuo root (K_slip = 0, P22).
    let kv: f64 = got[4][1].parse().unwrap();
    assert!((kv / 2.484875420273997 - 1.0).abs() < 1e-12);
}

#[test]
fn forward_rejects_missing_columns() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("cases.csv");
    std::fs::write(&input, "case_id,omega_rad_s\nx,1\n").unwrap();
    let st = pipewave()
        .args(["forward", "--input"])
        .arg(&input)
        .arg("--output")
        .arg(dir.path().join("o.csv"))
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&st.stderr).contains("missing column(s) fluid_density_kg_m3"));
}

/// `forward` writes to `--out`, named as in every other command; `--output`, its older name,
/// is still accepted and writes the same file.
#[test]
fn forward_takes_out_and_still_accepts_output() {
    let help = pipewave().args(["forward", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let usage = help.lines().find(|l| l.starts_with("Usage:")).unwrap();
    assert!(usage.contains("--out <FILE>"), "{usage}");
    assert!(help.contains("[alias: --output]"), "{help}");
    let dir = tempfile::tempdir().unwrap();
    let mut written = Vec::new();
    for name in ["--out", "--output"] {
        let out = dir.path().join(format!("results{name}.csv"));
        let st = pipewave()
            .args(["forward", "--input"])
            .arg(data_path("vectors/dispersion_roots.csv"))
            .arg(name)
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&st.stderr)
        );
        written.push(std::fs::read(&out).unwrap());
    }
    assert!(written[0] == written[1] && !written[0].is_empty());
}
