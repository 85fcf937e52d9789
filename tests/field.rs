//! The network soil field (model §7.12): coverage of its predicted speeds on a field drawn
//! from the model, the plan's preference for a measurement among many unmeasured pipes, and
//! the nightly run: every segment of the sample network gets a speed and an error.

use std::path::Path;
use std::process::Command;

use nalgebra::{DMatrix, DVector};
use pipewave::field::model::{dist, Field, Hyper, Observation, Sym2};
use pipewave::field::plan::{CandidateInput, Planner};
use pipewave::field::predict::{predict_speed, soil_of};
use pipewave::invert::{Method, Param, Problem, SegmentData};
use pipewave::physics::curves::{band_mean, curve, LEAK_BAND_HZ, STANDARD_GRID_HZ};
use pipewave::physics::inputs::{Fluid, Material, Pipe};
use pipewave::physics::{ContactMode, Model};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A standard normal deviate (Box–Muller).
fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The truth of the drawn fields: one class, ℓ = 400 m, a 20 % spread, 5 % scatter.
fn truth() -> (Hyper, [f64; 2]) {
    (
        Hyper {
            b: Sym2::new(0.04, 0.02, 0.05),
            ell: 400.0,
            t: Sym2::new(0.002, 0.0, 0.003),
        },
        [5.3, 4.6],
    )
}

/// Every point's true u (field + scatter) at `pos`, drawn exactly (dense Cholesky).
fn draw_u(rng: &mut ChaCha8Rng, pos: &[[f64; 2]], h: &Hyper, mu: [f64; 2]) -> Vec<[f64; 2]> {
    let n = pos.len();
    let mut k = DMatrix::<f64>::zeros(2 * n, 2 * n);
    for i in 0..n {
        for j in 0..n {
            let s = h.kernel(dist(pos[i], pos[j]));
            for a in 0..2 {
                for b in 0..2 {
                    k[(2 * i + a, 2 * j + b)] = s.at(a, b);
                }
            }
        }
    }
    let l = k.cholesky().expect("positive definite").l();
    let w = l * DVector::from_fn(2 * n, |_, _| normal(rng));
    let tl = h.t.cholesky().unwrap();
    (0..n)
        .map(|i| {
            let (a, b) = (normal(rng), normal(rng));
            [
                mu[0] + w[2 * i] + tl[0] * a,
                mu[1] + w[2 * i + 1] + tl[1] * a + tl[2] * b,
            ]
        })
        .collect()
}

/// A PVC main (110 mm SDR 11) in soil of density 1900 kg/m³, without measurements.
fn pvc_pipe() -> SegmentData {
    SegmentData {
        fluid: Fluid::water(),
        pipe: Pipe::from_outside_diameter(Material::Pvc.typical(), 0.110, 0.010).unwrap(),
        soil_density: 1900.0,
        material: Some(Material::Pvc),
        measurements: Vec::new(),
    }
}

/// The leak-band speed of `data` in the soil u with contact ξ (the forward model alone).
fn true_speed(data: &SegmentData, u: [f64; 2], xi: f64) -> f64 {
    let p = Problem::new(
        data,
        Method::Default,
        Model::Seed,
        ContactMode::Reciprocal,
        &[],
    );
    let (e, nu) = soil_of(u, data.soil_density).unwrap();
    let x: Vec<f64> = p
        .specs
        .iter()
        .map(|s| match s.param {
            Param::SoilModulus => s.coordinate(e),
            Param::SoilPoisson => nu,
            _ => xi,
        })
        .collect();
    let sys = p.system_at(&x).unwrap();
    let pts: Vec<(f64, Option<f64>)> = curve(&sys, &STANDARD_GRID_HZ)
        .iter()
        .map(|c| (c.frequency_hz, c.status.is_ok().then_some(c.phase_speed)))
        .collect();
    band_mean(&pts, LEAK_BAND_HZ).unwrap()
}

/// Plastic pipes whose soil is drawn from the model: the field learned from 40 measured ones
/// predicts the leak-band speed of 80 others (true contact drawn uniformly) with the truth
/// inside 2σ for 85–100 % of them.
#[test]
fn predicted_speeds_cover_the_truth() {
    let mut rng = ChaCha8Rng::seed_from_u64(38);
    let (h, mu) = truth();
    let pos: Vec<[f64; 2]> = (0..120)
        .map(|_| [rng.gen_range(0.0..2000.0), rng.gen_range(0.0..2000.0)])
        .collect();
    let u = draw_u(&mut rng, &pos, &h, mu);
    // A plastic pipe's fit: c_P to 2 %, c_S to 3 %, correlated.
    let info = Sym2::new(2500.0, 500.0, 1100.0);
    let noise = info.inverse().unwrap().cholesky().unwrap();
    let obs: Vec<Observation> = (0..40)
        .map(|i| {
            let (a, b) = (normal(&mut rng), normal(&mut rng));
            Observation {
                pos: Some(pos[i]),
                class: 0,
                u: [
                    u[i][0] + noise[0] * a,
                    u[i][1] + noise[1] * a + noise[2] * b,
                ],
                info,
                key: i as u64 * 7919 % 40,
                suspect: false,
            }
        })
        .collect();
    let field = Field::fit(obs, 1, (50.0, 2828.0));
    let data = pvc_pipe();
    let mut inside = 0;
    let mut widths = Vec::new();
    for i in 40..120 {
        let post = field.posterior(Some(pos[i]), 0, None);
        let pred = predict_speed(
            &data,
            Model::Seed,
            ContactMode::Reciprocal,
            post.mean,
            post.cov,
            field.widening,
        );
        let b = pred.band.expect("a predicted speed");
        let truth = true_speed(&data, u[i], rng.gen_range(0.0..1.0));
        if (b.value - truth).abs() <= 2.0 * b.std {
            inside += 1;
        }
        widths.push(2.0 * b.std / b.value);
    }
    let frac = inside as f64 / 80.0;
    widths.sort_by(f64::total_cmp);
    assert!(
        (0.85..=1.0).contains(&frac),
        "coverage {frac}, median 2 sigma {}",
        widths[40]
    );
    // Sharp, not merely wide: the median 2σ is below the spread of the soil itself (the
    // field's 20 % in c_S moves a PVC pipe's speed by about 10 %).
    assert!(widths[40] < 0.10, "median 2 sigma {}", widths[40]);
}

/// A measurement among many unmeasured pipes is worth more than one of an isolated pipe, and
/// each pick is valued after the earlier ones (the second gain is below the first).
#[test]
fn plan_prefers_a_pick_among_many_unmeasured_pipes() {
    let mut rng = ChaCha8Rng::seed_from_u64(83);
    let (h, mu) = truth();
    // Measured pipes along the west edge; a cluster of 20 unmeasured pipes and one isolated.
    let measured: Vec<[f64; 2]> = (0..15).map(|i| [0.0, i as f64 * 200.0]).collect();
    let u = draw_u(&mut rng, &measured, &h, mu);
    let info = Sym2::new(2500.0, 500.0, 1100.0);
    let obs: Vec<Observation> = measured
        .iter()
        .zip(&u)
        .enumerate()
        .map(|(i, (p, u))| Observation {
            pos: Some(*p),
            class: 0,
            u: *u,
            info,
            key: i as u64,
            suspect: false,
        })
        .collect();
    let field = Field::with_hyper(
        obs,
        1,
        (50.0, 4000.0),
        h,
        pipewave::field::model::HyperSource::Defaults,
    );
    let mut pos: Vec<[f64; 2]> = (0..20)
        .map(|_| {
            [
                1500.0 + rng.gen_range(-150.0..150.0),
                1500.0 + rng.gen_range(-150.0..150.0),
            ]
        })
        .collect();
    pos.push([1500.0, 4500.0]);
    let inputs: Vec<CandidateInput> = pos
        .iter()
        .enumerate()
        .map(|(i, p)| CandidateInput {
            site: i,
            pos: *p,
            class: 0,
            weight: 100.0,
            speed: 400.0,
            gradient: [60.0, 120.0],
            cov: field.posterior(Some(*p), 0, None).cov,
            info,
        })
        .collect();
    let planner = Planner::new(&field, inputs);
    let isolated = planner.gain(20, &[]);
    let picks = planner.pick(3);
    assert!(picks[0].0 < 20, "first pick {:?}", picks[0]);
    assert!(picks[0].1 > 2.0 * isolated, "{} vs {isolated}", picks[0].1);
    assert!(picks[1].1 < picks[0].1, "{picks:?}");
    // The gain of the first pick, valued again after it is taken, is nothing.
    assert_eq!(planner.gain(picks[0].0, &[picks[0].0]), 0.0);
}

fn pipewave() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

/// Copy the sample network, keeping the measurements of one segment in three.
fn sample_with_a_third_measured(dir: &Path) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network");
    std::fs::copy(src.join("segments.csv"), dir.join("segments.csv")).unwrap();
    let text = std::fs::read_to_string(src.join("measurements.csv")).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let mut ids: Vec<&str> = Vec::new();
    let mut out = vec![header.to_string()];
    for l in lines {
        let id = l.split(',').next().unwrap();
        if !ids.contains(&id) {
            ids.push(id);
        }
        if ids.iter().position(|x| *x == id).unwrap() % 3 == 0 {
            out.push(l.to_string());
        }
    }
    std::fs::write(dir.join("measurements.csv"), out.join("\n") + "\n").unwrap();
}

/// `pipewave run` on the sample network with a third of it measured: every exported segment
/// has a speed and an error, its source, and measured rows the field's own speed; `plan`
/// writes and stores its picks, and the GeoPackage carries them and the soil field.
#[test]
fn every_segment_of_the_sample_network_gets_a_speed() {
    let dir = tempfile::tempdir().unwrap();
    sample_with_a_third_measured(dir.path());
    let out = pipewave().arg("run").arg(dir.path()).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let field_line = stdout.lines().find(|l| l.starts_with("field: ")).unwrap();
    assert!(
        field_line.contains("segments predicted from"),
        "{field_line}"
    );

    let mut rdr = csv::Reader::from_path(dir.path().join("out/segments.csv")).unwrap();
    let headers = rdr.headers().unwrap().clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    };
    let (speed, std, source, reason) = (
        col("leak_band_speed_m_per_s"),
        col("leak_band_speed_std_m_per_s"),
        col("speed_source"),
        col("speed_source_reason"),
    );
    let (field_speed, field_std) = (
        col("field_leak_band_speed_m_per_s"),
        col("field_leak_band_speed_std_m_per_s"),
    );
    col("field_z");
    col("field_outlier");
    let (mut fitted, mut predicted) = (0, 0);
    for r in rdr.records() {
        let r = r.unwrap();
        let num = |i: usize| r[i].parse::<f64>().ok();
        let id = &r[0];
        assert!(
            num(speed).is_some_and(|v| v > 50.0 && v < 1600.0),
            "{id}: speed {}",
            &r[speed]
        );
        assert!(num(std).is_some_and(|v| v > 0.0), "{id}: error {}", &r[std]);
        match &r[source] {
            "fitted" => {
                fitted += 1;
                assert!(
                    num(field_speed).is_some() && num(field_std).is_some(),
                    "{id}"
                );
            }
            "predicted" => {
                predicted += 1;
                assert!(!r[reason].is_empty(), "{id}");
            }
            other => panic!("{id}: speed_source {other}: {}", &r[reason]),
        }
    }
    assert!(
        fitted > 50 && predicted > 100,
        "{fitted} fitted, {predicted} predicted"
    );

    // The plan: five picks, best first, stored and written as a GeoPackage layer.
    let db = dir.path().join("pipewave.sqlite");
    let next = dir.path().join("next.csv");
    let out = pipewave()
        .args(["plan", "--count", "5", "--db"])
        .arg(&db)
        .arg("--out")
        .arg(&next)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut rdr = csv::Reader::from_path(&next).unwrap();
    let h = rdr.headers().unwrap().clone();
    assert_eq!(&h[0], "segment_id");
    assert!(h.iter().any(|c| c == "expected_gain"));
    assert!(h.iter().any(|c| c == "leak_band_speed_std_m_per_s"));
    let gains: Vec<f64> = rdr
        .records()
        .map(|r| r.unwrap()[2].parse::<f64>().unwrap())
        .collect();
    assert_eq!(gains.len(), 5);
    assert!(gains.windows(2).all(|w| w[0] >= w[1]), "{gains:?}");
    let gpkg = dir.path().join("again.gpkg");
    let out = pipewave()
        .args(["export", "--format", "gpkg", "--db"])
        .arg(&db)
        .arg("--out")
        .arg(&gpkg)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let conn = rusqlite::Connection::open(&gpkg).unwrap();
    let count = |t: &str| -> i64 {
        conn.query_row(&format!("SELECT COUNT(*) FROM {t}"), [], |r| r.get(0))
            .unwrap()
    };
    assert_eq!(count("next_measurements"), 5);
    assert_eq!(count("soil_field"), count("pipe_segments"));
}

/// A zoned synthetic network through import and calibrate: each declared zone's class in the
/// field has the zone's own estimate (model §7.11) as its mean, the very soil stored in
/// `zone_fits`, and as its error the spread of that estimate (its 95 % interval in the speeds
/// spans about ±1.96 of the class's stated σ); the summary still reports the zones.
#[test]
fn a_zone_class_mean_is_the_zone_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    let db = dir.path().join("z.db");
    let ok = |out: std::process::Output| {
        let stdout = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(
            out.status.success(),
            "{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        stdout
    };
    ok(pipewave()
        .args([
            "synth",
            "--segments",
            "64",
            "--zones",
            "4",
            "--measured-fraction",
            "0.5",
        ])
        .args(["--defects", "0", "--no-real-cases", "--seed", "7", "--out"])
        .arg(&net)
        .output()
        .unwrap());
    ok(pipewave()
        .args(["import", "--db"])
        .arg(&db)
        .arg("--segments")
        .arg(net.join("segments.csv"))
        .arg("--measurements")
        .arg(net.join("measurements.csv"))
        .output()
        .unwrap());
    let stdout = ok(pipewave()
        .args(["calibrate", "--jobs", "1", "--db"])
        .arg(&db)
        .output()
        .unwrap());
    assert!(stdout.contains("zones: 4 estimated"), "{stdout}");
    let conn = rusqlite::Connection::open(&db).unwrap();
    let mut stmt = conn
        .prepare(
            "SELECT z.soil_zone, z.soil_p_wave_speed_m_per_s, z.soil_s_wave_speed_m_per_s, \
             z.soil_p_wave_speed_lo_m_per_s, z.soil_p_wave_speed_hi_m_per_s, \
             z.soil_s_wave_speed_lo_m_per_s, z.soil_s_wave_speed_hi_m_per_s, \
             c.mean_ln_cp, c.mean_ln_cs, c.std_ln_cp, c.std_ln_cs \
             FROM zone_fits z JOIN field_classes c ON c.soil_class = z.soil_zone \
             WHERE c.field_run_id = (SELECT MAX(id) FROM field_runs)",
        )
        .unwrap();
    let rows: Vec<(String, [f64; 10])> = stmt
        .query_map([], |r| {
            let mut v = [0.0; 10];
            for (k, x) in v.iter_mut().enumerate() {
                *x = r.get(k + 1)?;
            }
            Ok((r.get(0)?, v))
        })
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(rows.len(), 4);
    for (zone, v) in &rows {
        let [cp, cs, cp_lo, cp_hi, cs_lo, cs_hi, m_cp, m_cs, s_cp, s_cs] = *v;
        assert!((m_cp - cp.ln()).abs() < 1e-9, "{zone}: {m_cp} vs ln {cp}");
        assert!((m_cs - cs.ln()).abs() < 1e-9, "{zone}: {m_cs} vs ln {cs}");
        for (lo, hi, s) in [(cp_lo, cp_hi, s_cp), (cs_lo, cs_hi, s_cs)] {
            let half = 0.5 * (hi / lo).ln() / 1.96;
            assert!(
                s > 0.7 * half && s < 1.4 * half,
                "{zone}: class σ {s} against the interval's {half}"
            );
        }
    }
}
