//! `pipewave fit`: fitting from CSV files without keeping a database gives the same fits as
//! `run` on the same files, and bad input fits nothing.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn column(path: &std::path::Path, name: &str) -> Vec<(String, String)> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    let i = h.iter().position(|c| c == name).unwrap();
    r.records()
        .map(|x| {
            let x = x.unwrap();
            (x[0].to_string(), x[i].to_string())
        })
        .collect()
}

#[test]
fn fit_from_csv_equals_run() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    let st = bin()
        .args([
            "synth",
            "--segments",
            "4",
            "--seed",
            "9",
            "--no-real-cases",
            "--out",
        ])
        .arg(&net)
        .status()
        .unwrap();
    assert!(st.success());
    let out = tmp.path().join("fits.csv");
    let st = bin()
        .args(["fit", "--jobs", "2", "--segments"])
        .arg(net.join("segments.csv"))
        .arg("--measurements")
        .arg(net.join("measurements.csv"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    assert!(!tmp.path().join("net/pipewave.sqlite").exists());
    let st = bin().arg("run").arg(&net).output().unwrap();
    assert!(st.status.success());
    let a = column(&out, "soil_youngs_modulus_pa");
    let b = column(&net.join("out/segments.csv"), "soil_youngs_modulus_pa");
    assert_eq!(a.len(), 4);
    assert_eq!(a, b, "same inputs and seed give the same fits");
    assert!(a.iter().all(|(_, e)| e.parse::<f64>().unwrap() > 0.0));
}

#[test]
fn fit_with_a_bad_row_fits_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let seg = tmp.path().join("s.csv");
    let meas = tmp.path().join("m.csv");
    std::fs::write(
        &seg,
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\nA,XX,170,6,1900\n",
    )
    .unwrap();
    std::fs::write(
        &meas,
        "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m\nA,500,2.4,0.006\n",
    )
    .unwrap();
    let out = tmp.path().join("o.csv");
    let st = bin()
        .args(["fit", "--segments"])
        .arg(&seg)
        .arg("--measurements")
        .arg(&meas)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(st.status.code(), Some(2));
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("s.csv:2:2: column material"), "{err}");
    assert!(!out.exists());
}
