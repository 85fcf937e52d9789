//! Record errors and unit mix-ups (model §8 E8): a plastic wall recorded in the wrong SDR is a
//! record to check, never a thinned wall; measurements recorded in other units are named with
//! their factor and converted only on the user's confirmation; the sample network's WM10052
//! (attenuation entered in dB/m) is named as such. The trials that measure the acceptance rates
//! are `cargo run --release --example record_trials`.

use std::path::Path;

use pipewave::diagnose::inventory::{InventoryPipe, InventoryProfile};
use pipewave::diagnose::report::candidates_chi2;
use pipewave::diagnose::units::{UnitMixUp, DB_PER_NEPER};
use pipewave::diagnose::{diagnose_segment, prepare, DiagnoseSettings};
use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::synth::trial::{effect_trial, trial};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
mod common;
use common::cli::ok;

#[test]
fn unit_mix_ups_are_named_with_their_factor() {
    // The physical effects and the units (the record check is left out to keep this fast: a
    // unit mix-up is a constant factor no record reproduces at every frequency).
    let settings = DiagnoseSettings {
        candidates: vec![
            Effect::SoilDamping,
            Effect::AirInWater,
            Effect::WallThinning,
            Effect::PipeLoss,
            Effect::ViscoelasticWall,
            Effect::MeasurementUnits,
        ],
        ..DiagnoseSettings::default()
    };
    let cases = [
        (
            Material::DuctileIron,
            Some(UnitMixUp::AttenuationInDb),
            1u64,
        ),
        (Material::Mdpe, Some(UnitMixUp::AttenuationInDb), 2),
        (Material::CastIron, Some(UnitMixUp::OmegaAsFrequency), 3),
        (Material::Pvc, Some(UnitMixUp::FrequencyAsOmega), 4),
        (Material::DuctileIron, None, 5),
        (Material::Hdpe, None, 6),
    ];
    let out: Vec<_> = cases
        .par_iter()
        .map(|&(m, mix, seed)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            // A mix-up is detectable only where the model cannot absorb it (a soft plastic pipe
            // in a stiff soil can radiate several times more): draw until the recorded data
            // leave a misfit far above the noise.
            let t = loop {
                let Some(mut t) = effect_trial(&mut rng, m, None) else {
                    continue;
                };
                // Record the true data in the wrong units: the inverse of what is undone.
                let Some(u) = mix else { break t };
                for x in &mut t.data.measurements {
                    match u {
                        UnitMixUp::AttenuationInDb | UnitMixUp::AttenuationDividedByDb => {
                            x.attenuation *= u.factor();
                            x.attenuation_std = x.attenuation_std.map(|s| s * u.factor());
                        }
                        _ => x.omega *= u.factor(),
                    }
                }
                if prepare(&t.data, None, &settings).structure.structured {
                    break t;
                }
            };
            (m, mix, diagnose_segment(&t.data, None, &settings))
        })
        .collect();
    for (m, mix, d) in out {
        match mix {
            Some(u) => {
                // Named, or reported beside a physical effect the data cannot tell from it
                // (a wall loss can scale the attenuation of a stiff pipe as a unit does).
                assert!(
                    d.named == Some(Effect::MeasurementUnits)
                        || d.ambiguous_with.contains(&Effect::MeasurementUnits),
                    "{m:?} {u:?}: named {:?}, also {:?}; {}",
                    d.named,
                    d.ambiguous_with,
                    candidates_chi2(&d)
                );
                assert_eq!(d.units.as_ref().map(|x| x.0), Some(u), "{m:?}");
                // The unit refit explains the data (its χ² within the noise, the acceptance
                // rule).
                let units_refit = d
                    .candidates
                    .iter()
                    .find(|c| c.effect == Effect::MeasurementUnits)
                    .and_then(|c| c.refit.as_ref());
                assert!(
                    units_refit.is_some_and(|r| r.explains),
                    "{m:?} {u:?}: {}",
                    candidates_chi2(&d)
                );
            }
            None => assert_ne!(d.named, Some(Effect::MeasurementUnits), "{m:?} control"),
        }
    }
    assert!((UnitMixUp::AttenuationInDb.factor() - DB_PER_NEPER).abs() < 1e-15);
}

#[test]
fn a_plastic_wall_in_the_wrong_sdr_is_a_record_not_thinning() {
    // An HDPE 180 recorded as SDR 11 (16.4 mm) that is really SDR 17 (10.7 mm): the fitted
    // "thinning" ratio would be 10.7/16.4 = 0.65, but a PE wall does not thin.
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let t = loop {
        if let Some(t) = trial(
            &mut rng,
            Material::Hdpe,
            (180.0, 10.7),
            None,
            (Material::Hdpe, 180.0, 16.4),
        ) {
            break t;
        }
    };
    let pipe = |material, od_mm, wall_mm| InventoryPipe {
        material,
        od_mm,
        wall_mm,
        install_year: Some(2000),
    };
    let settings = DiagnoseSettings {
        inventory: Some(std::sync::Arc::new(InventoryProfile {
            pipes: vec![
                pipe(Material::Hdpe, 180.0, 10.7),
                pipe(Material::Hdpe, 180.0, 16.4),
                pipe(Material::DuctileIron, 170.0, 6.0),
            ],
        })),
        install_year: Some(2001),
        ..DiagnoseSettings::default()
    };
    let d = diagnose_segment(&t.data, None, &settings);
    assert!(d.structure.structured);
    assert!(d
        .candidates
        .iter()
        .all(|c| c.effect != Effect::WallThinning));
    assert_eq!(d.named, Some(Effect::InventoryError), "{:?}", d.named);
    let set = d.record_set_text();
    assert!(
        set.split(" | ")
            .any(|r| r == "material=HDPE; OD 180 mm; wall 10.7 mm"),
        "{set}"
    );
}

fn row(path: &Path, id: &str) -> std::collections::BTreeMap<String, String> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    r.records()
        .map(|x| x.unwrap())
        .find(|x| &x[0] == id)
        .map(|x| {
            h.iter()
                .zip(x.iter())
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect()
        })
        .unwrap()
}

#[test]
fn sample_network_wm10052_attenuation_in_db_per_m() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let net = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network");
    let db = tmp.path().join("net.sqlite");
    ok(&[
        "import",
        "--db",
        &s(&db),
        "--segments",
        &s(&net.join("segments.csv")),
        "--measurements",
        &s(&net.join("measurements.csv")),
    ]);
    // WM10052 is HDPE: wall thinning is skipped for it, with a note.
    ok(&[
        "calibrate",
        "--db",
        &s(&db),
        "--segment",
        "WM10052",
        "--effects",
        "wall_thinning",
        "--jobs",
        "2",
    ]);
    let conn = rusqlite::Connection::open(&db).unwrap();
    let (effects, message): (String, String) = conn
        .query_row(
            "SELECT effects, message FROM latest_fits WHERE segment_id = 'WM10052'",
            [],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    assert_eq!(effects, "");
    assert!(
        message.contains("wall_thinning skipped: HDPE walls neither corrode"),
        "{message}"
    );
    let att = |conn: &rusqlite::Connection| -> f64 {
        conn.query_row(
            "SELECT SUM(attenuation_np_per_m) FROM measurements WHERE segment_id = 'WM10052'",
            [],
            |r| r.get(0),
        )
        .unwrap()
    };
    let stored = att(&conn);
    let out = tmp.path().join("diag");
    let d = ok(&[
        "diagnose",
        "--db",
        &s(&db),
        "--segment",
        "WM10052",
        "--out",
        &s(&out),
        "--jobs",
        "2",
        "--no-apply",
    ]);
    let r = row(&out.join("diagnosis.csv"), "WM10052");
    assert_eq!(r["named_effect"], "measurement_units", "{r:?}");
    assert!(
        r["effect_value"].starts_with("attenuation recorded in dB/m, not Np/m (recorded = 8.686"),
        "{r:?}"
    );
    assert!(r["record_to_check"].contains("--convert-units WM10052=attenuation_db"));
    // Reported only: the stored measurements are unchanged.
    assert_eq!(att(&conn), stored, "{}", String::from_utf8_lossy(&d.stdout));
    // The user confirms: converted once, and a repeated confirmation changes nothing.
    for expect in ["converted 6 measurements", "not converted"] {
        let d = ok(&[
            "diagnose",
            "--db",
            &s(&db),
            "--segment",
            "WM10052",
            "--out",
            &s(&out),
            "--jobs",
            "2",
            "--convert-units",
            "WM10052=attenuation_db",
        ]);
        let stdout = String::from_utf8_lossy(&d.stdout);
        assert!(stdout.contains(&format!("WM10052: {expect}")), "{stdout}");
        assert!((att(&conn) * DB_PER_NEPER / stored - 1.0).abs() < 1e-12);
    }
    // The next calibrate refits the converted segment, which the model now explains.
    ok(&["calibrate", "--db", &s(&db), "--segment", "WM10052"]);
    let chi2: f64 = conn
        .query_row(
            "SELECT chi2_per_dof FROM latest_fits WHERE segment_id = 'WM10052'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!(chi2 < 2.0, "{chi2}");
}
