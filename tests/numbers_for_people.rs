//! The CSV and GeoJSON print numbers for people: an error to 2 significant digits and its
//! value (and interval ends) to the same decimal place, other values to 6 significant digits;
//! `--precision full` and the GeoPackage keep every digit; the correlator's columns come first.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use rusqlite::Connection;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn ok(args: &[&str]) {
    let out = bin().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Significant digits of a printed number: leading zeros never count; trailing zeros count
/// after a decimal point, not in a whole number (`380` has two, `1.0` two).
fn sig_digits(t: &str) -> usize {
    let mantissa = t.split('e').next().unwrap();
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    let digits = digits.trim_start_matches('0');
    if mantissa.contains('.') {
        digits.len()
    } else {
        digits.trim_end_matches('0').len()
    }
}

/// Decimals of a printed number.
fn decimals(t: &str) -> usize {
    t.split_once('.').map_or(0, |(_, d)| d.len())
}

fn rows(path: &Path) -> (Vec<String>, Vec<BTreeMap<String, String>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| {
            h.iter()
                .cloned()
                .zip(rec.unwrap().iter().map(String::from))
                .collect()
        })
        .collect();
    (h, rows)
}

#[test]
fn exports_round_to_the_error_unless_asked_for_every_digit() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    ok(&[
        "synth",
        "--out",
        s(&net),
        "--segments",
        "6",
        "--seed",
        "9",
        "--defects",
        "0",
        "--no-real-cases",
    ]);
    let db = tmp.path().join("n.sqlite");
    ok(&[
        "import",
        "--db",
        s(&db),
        "--segments",
        s(&net.join("segments.csv")),
        "--measurements",
        s(&net.join("measurements.csv")),
    ]);
    ok(&["calibrate", "--db", s(&db), "--jobs", "1"]);
    let people = tmp.path().join("people.csv");
    let full = tmp.path().join("full.csv");
    ok(&[
        "export",
        "--db",
        s(&db),
        "--format",
        "csv",
        "--out",
        s(&people),
    ]);
    ok(&[
        "export",
        "--db",
        s(&db),
        "--format",
        "csv",
        "--out",
        s(&full),
        "--precision",
        "full",
    ]);
    let (h, people) = rows(&people);
    let (hf, full) = rows(&full);
    assert_eq!(h, hf);
    assert_eq!(
        &h[..5],
        &[
            "segment_id",
            "leak_band_speed_m_per_s",
            "leak_band_speed_std_m_per_s",
            "status",
            "flags"
        ]
    );
    // Full precision: every digit of the database.
    let conn = Connection::open(&db).unwrap();
    let stored: BTreeMap<String, (f64, f64)> = conn
        .prepare(
            "SELECT segment_id, leak_band_speed_std_m_per_s, soil_p_wave_speed_m_per_s \
             FROM latest_fits",
        )
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, (r.get(1)?, r.get(2)?))))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(stored.len(), 6);
    for row in &full {
        let (std, cp) = stored[&row["segment_id"]];
        assert_eq!(
            row["leak_band_speed_std_m_per_s"].parse::<f64>().unwrap(),
            std
        );
        assert_eq!(row["soil_p_wave_speed_m_per_s"].parse::<f64>().unwrap(), cp);
    }
    // For people: errors 2 significant digits, values to their decimal place.
    let pairs = [
        ("leak_band_speed_m_per_s", "leak_band_speed_std_m_per_s"),
        ("soil_p_wave_speed_m_per_s", "soil_p_wave_speed_std_m_per_s"),
        ("soil_youngs_modulus_pa", "soil_youngs_modulus_std_pa"),
        ("soil_youngs_modulus_lo_pa", "soil_youngs_modulus_std_pa"),
        ("soil_poisson", "soil_poisson_std"),
    ];
    let mut checked = 0;
    for (p, f) in people.iter().zip(&full) {
        for (value, error) in pairs {
            let (v, e) = (&p[value], &p[error]);
            if v.is_empty() || e.is_empty() || e == "0" {
                continue;
            }
            checked += 1;
            // The full error rounded to 2 significant digits (a carry to the next decade
            // keeps 2 digits: 0.996 is 1.0) is what is printed; the value is rounded to the
            // same decimal place, and both show exactly that many decimals.
            let ef: f64 = f[error].parse().unwrap();
            let exp = ef.log10().floor() as i32;
            let round = |x: f64, place: i32| (x / 10f64.powi(place)).round() * 10f64.powi(place);
            let mut place = exp - 1;
            if round(ef, place) >= 10f64.powi(exp + 1) {
                place += 1;
            }
            let (ep, vp): (f64, f64) = (e.parse().unwrap(), v.parse().unwrap());
            let vf: f64 = f[value].parse().unwrap();
            // Within half a unit of the last digit kept (a tie may round either way).
            let tol = 0.500_001 * 10f64.powi(place);
            assert!(
                (ep - round(ef, place)).abs() <= tol,
                "{error}: {e} from {ef}"
            );
            assert!(
                (vp - round(vf, place)).abs() <= tol,
                "{value}: {v} from {vf} (± {e})"
            );
            let want_decimals = usize::try_from(-place).unwrap_or(0);
            assert_eq!(decimals(e), want_decimals, "{error} {e}");
            assert_eq!(decimals(v), want_decimals, "{value} {v} ± {e}");
            assert!(sig_digits(e) <= 2, "{error} {e}");
        }
        // Values without an error: at most 6 significant digits.
        for col in [
            "misfit",
            "chi2_per_dof",
            "speed_500hz_m_per_s",
            "outer_diameter_mm",
        ] {
            let v = &p[col];
            if !v.is_empty() {
                assert!(sig_digits(v) <= 6, "{col} {v}");
                let (vp, vf) = (v.parse::<f64>().unwrap(), f[col].parse::<f64>().unwrap());
                assert!((vp - vf).abs() <= 5e-6 * vf.abs(), "{col}: {v} from {vf}");
            }
        }
        assert!(
            p["leak_band_speed_m_per_s"].len() < 12,
            "{}",
            p["leak_band_speed_m_per_s"]
        );
    }
    assert!(checked >= 18, "{checked} pairs checked");

    // GeoJSON: the same rounding; the GeoPackage: every digit.
    let gj = tmp.path().join("n.geojson");
    ok(&[
        "export",
        "--db",
        s(&db),
        "--format",
        "geojson",
        "--out",
        s(&gj),
    ]);
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&gj).unwrap()).unwrap();
    for feat in doc["features"].as_array().unwrap() {
        let props = &feat["properties"];
        let id = props["segment_id"].as_str().unwrap();
        let row = people.iter().find(|r| r["segment_id"] == id).unwrap();
        for col in [
            "leak_band_speed_m_per_s",
            "leak_band_speed_std_m_per_s",
            "misfit",
        ] {
            assert_eq!(
                props[col].as_f64().unwrap(),
                row[col].parse::<f64>().unwrap(),
                "{id} {col}"
            );
        }
    }
    let gpkg = tmp.path().join("n.gpkg");
    ok(&[
        "export",
        "--db",
        s(&db),
        "--format",
        "gpkg",
        "--out",
        s(&gpkg),
    ]);
    let g = Connection::open(&gpkg).unwrap();
    let in_gpkg: BTreeMap<String, f64> = g
        .prepare("SELECT segment_id, leak_band_speed_std_m_per_s FROM pipe_segments")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    for (id, (std, _)) in &stored {
        assert_eq!(in_gpkg[id], *std, "{id}");
    }
}
