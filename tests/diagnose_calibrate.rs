//! The effects of issue 13 through `calibrate`, as a user runs it: `--effects inventory_error`
//! fits the candidate records and stores the one the data choose (named in the fit's message),
//! and `--effects viscoelastic_wall` stores the fitted exponent n in `fits.viscoelastic_exponent`.

use std::fmt::Write as _;
use std::path::Path;

use pipewave::physics::effects::Effect;
use pipewave::physics::Material;
use pipewave::synth::trial::{trial, Trial};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
mod common;
use common::cli::ok;

fn make(seed: u64, material: Material, size: (f64, f64), hidden: Option<(Effect, f64)>) -> Trial {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let record = (material, size.0, size.1);
    loop {
        if let Some(t) = trial(&mut rng, material, size, hidden, record) {
            return t;
        }
    }
}

/// Write the inventory and measurements of `segments` (id, recorded material code, trial).
fn write_csvs(dir: &Path, segments: &[(&str, &str, (f64, f64), &Trial)]) {
    let mut seg = String::from(
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n",
    );
    let mut meas = String::from(
        "segment_id,omega_rad_s,k_re_rad_per_m,attenuation_np_per_m,k_re_std,attenuation_std\n",
    );
    for (id, material, (od, wall), t) in segments {
        writeln!(seg, "{id},{material},{od},{wall},{}", t.data.soil_density).unwrap();
        for m in &t.data.measurements {
            writeln!(
                meas,
                "{id},{:e},{:e},{:e},{:e},{:e}",
                m.omega,
                m.k_re,
                m.attenuation,
                m.k_re_std.unwrap(),
                m.attenuation_std.unwrap()
            )
            .unwrap();
        }
    }
    std::fs::write(dir.join("segments.csv"), seg).unwrap();
    std::fs::write(dir.join("measurements.csv"), meas).unwrap();
}

struct Latest {
    effects: String,
    chi2_per_dof: f64,
    message: String,
    viscoelastic: (Option<f64>, Option<f64>),
}

fn latest(db: &Path, id: &str) -> Latest {
    let conn = rusqlite::Connection::open(db).unwrap();
    conn.query_row(
        "SELECT effects, chi2_per_dof, COALESCE(message, ''), viscoelastic_exponent, \
         viscoelastic_exponent_std FROM latest_fits WHERE segment_id = ?1",
        [id],
        |r| {
            Ok(Latest {
                effects: r.get(0)?,
                chi2_per_dof: r.get(1)?,
                message: r.get(2)?,
                viscoelastic: (r.get(3)?, r.get(4)?),
            })
        },
    )
    .unwrap()
}

#[test]
fn calibrate_with_inventory_error_stores_the_record_the_data_choose() {
    let tmp = tempfile::tempdir().unwrap();
    // A ductile-iron DN150 main (OD 170, wall 6.0) recorded as PVC 110 SDR 21 (the sample
    // network's wrong-material defect), and the same main recorded right.
    let wrong = make(11, Material::DuctileIron, (170.0, 6.0), None);
    let right = make(12, Material::DuctileIron, (170.0, 6.0), None);
    // An MDPE 180 SDR 11 pipe with a viscoelastic wall, n = 0.06.
    let ve = make(
        13,
        Material::Mdpe,
        (180.0, 16.4),
        Some((Effect::ViscoelasticWall, 0.06)),
    );
    write_csvs(
        tmp.path(),
        &[
            ("WRONG", "PVC", (110.0, 5.3), &wrong),
            ("RIGHT", "DI", (170.0, 6.0), &right),
            ("VE", "MDPE", (180.0, 16.4), &ve),
        ],
    );
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let db = tmp.path().join("p.sqlite");
    ok(&[
        "import",
        "--db",
        &s(&db),
        "--segments",
        &s(&tmp.path().join("segments.csv")),
        "--measurements",
        &s(&tmp.path().join("measurements.csv")),
    ]);
    // Plain calibrate: the wrong record leaves a gross misfit.
    ok(&["calibrate", "--db", &s(&db), "--jobs", "2"]);
    let plain = latest(&db, "WRONG");
    assert!(plain.chi2_per_dof > 20.0, "{}", plain.chi2_per_dof);
    assert_eq!(latest(&db, "VE").viscoelastic, (None, None));

    ok(&[
        "calibrate",
        "--db",
        &s(&db),
        "--jobs",
        "2",
        "--effects",
        "inventory_error",
        "--segment",
        "WRONG",
        "--segment",
        "RIGHT",
    ]);
    let w = latest(&db, "WRONG");
    assert_eq!(w.effects, "inventory_error");
    // The true material and diameter are named (DI OD 170 mm), alone or with a grey-iron
    // record of the same stiffness per length (E_p·h), which the data cannot tell from it. The
    // wall class is not asserted: the catalogue's K9 (6.0 mm) and K10 (6.5 mm) at DN 150 differ
    // by 8 % in E_p·h, and the 95 % record set can hold either.
    assert!(
        w.message
            .starts_with("inventory_error: measured data fit material=DI; OD 170 mm; wall ")
            && w.message
                .contains("this fit is made with the record material="),
        "{}",
        w.message
    );
    assert!(w.chi2_per_dof < 3.0, "{} ({})", w.chi2_per_dof, w.message);
    let r = latest(&db, "RIGHT");
    assert_eq!(r.effects, "inventory_error");
    assert!(
        r.message.starts_with("inventory_error: recorded pipe kept"),
        "{}",
        r.message
    );
    assert!(r.chi2_per_dof < 3.0, "{}", r.chi2_per_dof);

    // The viscoelastic exponent has its own column.
    ok(&[
        "calibrate",
        "--db",
        &s(&db),
        "--jobs",
        "2",
        "--effects",
        "viscoelastic_wall",
        "--segment",
        "VE",
    ]);
    let v = latest(&db, "VE");
    assert_eq!(v.effects, "viscoelastic_wall");
    let (n, n_std) = (v.viscoelastic.0.unwrap(), v.viscoelastic.1.unwrap());
    assert!(
        (n - 0.06).abs() <= 3.0 * n_std && n_std < 0.02,
        "n = {n} ± {n_std}"
    );
}
