//! The database layer through the library: inventory reads as physics inputs, and the round trip
//! of runs, fits and curves, on a temporary database file.

use pipewave::db::{
    self, curves_for, finish_run, insert_fit_with_curves, latest_fits, load_run, load_segment,
    load_segments, segments_needing_fit, start_run, CurvePoint, Database, DbError, FitRow,
    FitStatus, ImportOptions, ImportSource, NewRun, RunCounts, RunStatus,
};
use pipewave::physics::{ContactMode, Material, Model};
use tempfile::TempDir;

const SEGMENTS: &str = "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3,pipe_youngs_modulus_pa\n\
    A,DI,170,6,1900,1.6e11\nB,PVC,110,5.3,1800,\nC,CI,150,8,2000,\n";
const MEASUREMENTS: &str = "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m,k_re_std\n\
    A,200,1.1,0.004,0.01\nA,100,0.55,0.002,0.01\nB,100,0.9,0.05,\n";

fn setup() -> (TempDir, Database) {
    let dir = tempfile::tempdir().unwrap();
    let mut database = Database::open(dir.path().join("t.sqlite")).unwrap();
    let report = db::import(
        database.conn_mut(),
        Some(&ImportSource::from_bytes("segments.csv", SEGMENTS)),
        Some(&ImportSource::from_bytes("measurements.csv", MEASUREMENTS)),
        ImportOptions::default(),
    )
    .unwrap();
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    (dir, database)
}

fn new_run(seed: u64) -> NewRun {
    NewRun {
        seed,
        model: Model::Full,
        contact_mode: ContactMode::Reciprocal,
        method: "default".into(),
        effects: String::new(),
        program_version: env!("CARGO_PKG_VERSION").into(),
        jobs: Some(2),
        n_segments: 2,
    }
}

fn fit(database: &Database, id: &str, run: i64, settings: &str) -> FitRow {
    let seg = load_segment(database.conn(), id).unwrap().unwrap();
    let mut f = FitRow::new(id, run, FitStatus::Ok, Model::Full, ContactMode::Reciprocal);
    f.soil_youngs_modulus_pa = Some(5e7);
    f.soil_poisson = Some(0.35);
    f.contact = Some(0.0);
    f.soil_youngs_modulus_std_pa = Some(2e6);
    f.air_fraction = Some(1e-4);
    f.misfit = Some(0.0123);
    f.chi2_per_dof = Some(1.07);
    f.n_measurements = Some(2);
    f.correlations = Some("[[1,0.2],[0.2,1]]".into());
    f.flags = "high_condition".into();
    f.flag_reasons = "condition number 1e9".into();
    f.soil_p_wave_speed_m_per_s = Some(212.0);
    f.soil_p_wave_speed_std_m_per_s = Some(9.0);
    f.soil_s_wave_speed_m_per_s = Some(96.0);
    f.soil_s_wave_speed_std_m_per_s = Some(40.0);
    f.soil_youngs_modulus_lo_pa = Some(1.2e7);
    f.soil_youngs_modulus_hi_pa = Some(8.1e7);
    f.soil_poisson_lo = Some(0.0);
    f.soil_poisson_hi = Some(0.499);
    f.contact_lo = Some(0.1);
    f.contact_hi = Some(0.7);
    f.leak_band_speed_m_per_s = Some(1183.0);
    f.leak_band_speed_std_m_per_s = Some(6.0);
    f.notes = "soil_via_cp".into();
    f.note_reasons = "soil_via_cp: E_m and nu_m known only through c_P = 212 ± 9 m/s".into();
    f.algorithm_version = Some(pipewave::types::FIT_ALGORITHM_VERSION);
    f.evaluations = Some(4200);
    f.seed = Some(u64::MAX - 5);
    f.inputs_hash = seg.inputs_hash;
    f.settings_hash = settings.into();
    f.elapsed_ms = Some(812.5);
    f
}

#[test]
fn segments_read_back_as_checked_physics_inputs() {
    let (_dir, database) = setup();
    let all = load_segments(database.conn(), None).unwrap();
    let ids: Vec<&str> = all.iter().map(|s| s.segment_id.as_str()).collect();
    assert_eq!(ids, ["A", "B", "C"]);
    let a = &all[0];
    assert_eq!(a.material, Material::DuctileIron);
    // Measurements sorted by ω whatever the file order; ω = 2πf.
    let f: Vec<f64> = a.measurements.iter().map(|m| m.frequency_hz).collect();
    assert_eq!(f, [100.0, 200.0]);
    // Mean radius (170 − 6)/2 mm = 0.082 m, eq. P6; E_p overridden, ν_p from the material.
    let pipe = a.pipe().unwrap();
    assert!((pipe.mean_radius - 0.082).abs() < 1e-12);
    assert_eq!(pipe.youngs_modulus, 1.6e11);
    assert_eq!(pipe.poisson, Material::DuctileIron.typical().poisson);
    assert_eq!(a.fluid().unwrap().density, 1000.0);
    assert_eq!(a.soil_density().unwrap(), 1900.0);
    assert_eq!(
        Some(a.inputs_hash.clone()),
        db::stored_inputs_hash(database.conn(), "A").unwrap()
    );

    let some = load_segments(database.conn(), Some(&["C".into(), "A".into()])).unwrap();
    assert_eq!(some.len(), 2);
    let err = load_segments(database.conn(), Some(&["A".into(), "X9".into()])).unwrap_err();
    assert!(
        matches!(err, DbError::UnknownSegments { ref ids } if ids == "X9"),
        "{err}"
    );
    assert!(load_segment(database.conn(), "X9").unwrap().is_none());
}

#[test]
fn runs_fits_and_curves_round_trip() {
    let (_dir, mut database) = setup();
    let run = start_run(database.conn(), &new_run(u64::MAX)).unwrap();
    let f = fit(&database, "A", run, "s1");
    let curve = [
        CurvePoint {
            frequency_hz: 200.0,
            phase_speed_m_per_s: Some(1150.0),
            attenuation_db_per_m: Some(0.04),
            phase_speed_std_m_per_s: Some(6.0),
            attenuation_std_db_per_m: Some(0.003),
            model_phase_speed_m_per_s: Some(1100.0),
            model_attenuation_db_per_m: None,
        },
        CurvePoint {
            frequency_hz: 100.0,
            phase_speed_m_per_s: None,
            attenuation_db_per_m: None,
            phase_speed_std_m_per_s: None,
            attenuation_std_db_per_m: None,
            model_phase_speed_m_per_s: None,
            model_attenuation_db_per_m: None,
        },
    ];
    let id = insert_fit_with_curves(database.conn_mut(), &f, &curve).unwrap();
    finish_run(
        database.conn(),
        run,
        &RunCounts {
            n_ok: 1,
            n_flagged: 0,
            n_failed: 0,
            elapsed_s: Some(1.5),
        },
        RunStatus::Finished,
    )
    .unwrap();

    let latest = latest_fits(database.conn(), None).unwrap();
    assert_eq!(latest.len(), 1);
    let got = &latest[0];
    assert_eq!(got.id, Some(id));
    assert!(got.created_at.is_some());
    let mut expected = f.clone();
    expected.id = got.id;
    expected.created_at = got.created_at.clone();
    assert_eq!(got, &expected);

    let points = curves_for(database.conn(), "A", run).unwrap();
    assert_eq!(points, [curve[1], curve[0]]);

    let r = load_run(database.conn(), run).unwrap().unwrap();
    assert_eq!(r.status, RunStatus::Finished);
    assert_eq!(r.settings, new_run(u64::MAX));
    assert_eq!(r.counts.n_ok, 1);
    assert!(r.finished_at.is_some());
}

#[test]
fn a_fit_and_its_curve_are_stored_together_or_not_at_all() {
    let (_dir, mut database) = setup();
    let run = start_run(database.conn(), &new_run(1)).unwrap();
    let f = fit(&database, "A", run, "s1");
    let p = CurvePoint {
        frequency_hz: 100.0,
        phase_speed_m_per_s: Some(1000.0),
        attenuation_db_per_m: Some(0.1),
        phase_speed_std_m_per_s: None,
        attenuation_std_db_per_m: None,
        model_phase_speed_m_per_s: None,
        model_attenuation_db_per_m: None,
    };
    // The same frequency twice violates the curve's primary key after the fit row is written.
    assert!(insert_fit_with_curves(database.conn_mut(), &f, &[p, p]).is_err());
    assert!(latest_fits(database.conn(), None).unwrap().is_empty());
    // A fit of a segment that is not in the inventory is refused by the foreign key.
    let ghost = FitRow::new(
        "X9",
        run,
        FitStatus::Failed,
        Model::Seed,
        ContactMode::Blend,
    );
    assert!(insert_fit_with_curves(database.conn_mut(), &ghost, &[]).is_err());
}

#[test]
fn segments_needing_fit_follow_inputs_and_settings() {
    let (_dir, mut database) = setup();
    // C has no measurements: never scheduled.
    assert_eq!(
        segments_needing_fit(database.conn(), "s1", false).unwrap(),
        ["A", "B"]
    );
    let run = start_run(database.conn(), &new_run(7)).unwrap();
    for id in ["A", "B"] {
        let f = fit(&database, id, run, "s1");
        insert_fit_with_curves(database.conn_mut(), &f, &[]).unwrap();
    }
    assert!(segments_needing_fit(database.conn(), "s1", false)
        .unwrap()
        .is_empty());
    assert_eq!(
        segments_needing_fit(database.conn(), "s1", true).unwrap(),
        ["A", "B"]
    );
    assert_eq!(
        segments_needing_fit(database.conn(), "s2", false).unwrap(),
        ["A", "B"]
    );
    // New measurements for B change its inputs_hash: only B needs a refit.
    db::import(
        database.conn_mut(),
        None,
        Some(&ImportSource::from_bytes(
            "m2.csv",
            "segment_id,frequency_hz,k_re_rad_per_m,attenuation_np_per_m\nB,100,0.91,0.05\n",
        )),
        ImportOptions::default(),
    )
    .unwrap();
    assert_eq!(
        segments_needing_fit(database.conn(), "s1", false).unwrap(),
        ["B"]
    );
    // A newer fit of B with the new hash satisfies it; the view picks the newest fit.
    let run2 = start_run(database.conn(), &new_run(8)).unwrap();
    let f = fit(&database, "B", run2, "s1");
    insert_fit_with_curves(database.conn_mut(), &f, &[]).unwrap();
    assert!(segments_needing_fit(database.conn(), "s1", false)
        .unwrap()
        .is_empty());
    let latest = latest_fits(database.conn(), Some(&["B".into()])).unwrap();
    assert_eq!(latest[0].run_id, run2);
    let all = latest_fits(database.conn(), None).unwrap();
    assert_eq!(
        all.iter()
            .map(|f| (f.segment_id.as_str(), f.run_id))
            .collect::<Vec<_>>(),
        [("A", run), ("B", run2)]
    );
}

#[test]
fn opening_twice_and_concurrent_calibrate_lock() {
    let (dir, mut database) = setup();
    // A second connection (another process would do the same) sees a migrated database.
    let mut other = Database::open(dir.path().join("t.sqlite")).unwrap();
    assert_eq!(
        other.schema_version().unwrap(),
        pipewave::db::migrate::latest_version()
    );
    // One version per file in migrations/.
    let files = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/migrations"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "sql")
        })
        .count();
    assert_eq!(pipewave::db::migrate::latest_version(), files as i64);
    let lock = db::try_acquire_run_lock(database.conn_mut()).unwrap();
    let err = db::try_acquire_run_lock(other.conn_mut()).unwrap_err();
    assert!(
        err.to_string().contains(&format!(
            "another calibrate run (pid {}, started {})",
            lock.pid, lock.started_at
        )),
        "{err}"
    );
    db::release_run_lock(database.conn(), &lock).unwrap();
    let lock2 = db::try_acquire_run_lock(other.conn_mut()).unwrap();
    db::release_run_lock(other.conn(), &lock2).unwrap();
}
