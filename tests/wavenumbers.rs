//! `pipewave wavenumbers`: field wavenumbers from hydrant-test recordings (model §10).
//!
//! The acceptance of issue 15 on synthetic recordings made here with a seed the code was not
//! tuned on (iron and plastic pipes, sensors 6–80 m from the source, sensor noise 30 % of the
//! source channel, 30 s at 8 kHz), the fit of the resulting measurements, and the messages for
//! field mistakes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use pipewave::physics::{ContactMode, Fluid, Material, Model, Soil, System};
use pipewave::synth::recordings::{
    hydrant_test, seed_layout, sensor_range_m, write_wav, HydrantRecording, RecordingSpec,
    TruthCurve, WavFormat,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The seed of the acceptance recordings: chosen when the test was written, after the estimator
/// was tuned on seeds 1–10 of examples/wavenumbers_coverage.rs; not changed since.
const ACCEPTANCE_SEED: u64 = 0x15_2026_1122;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pipewave"))
}

fn run(args: &[&std::ffi::OsStr]) -> Output {
    bin().args(args).output().expect("run pipewave")
}

/// One synthetic pipe of the acceptance set.
struct TestPipe {
    id: String,
    material: Material,
    od_mm: f64,
    wall_mm: f64,
    soil: Soil,
    positions: Vec<f64>,
    rec: HydrantRecording,
}

fn make_pipe(rng: &mut ChaCha8Rng, id: &str, material: Material, seconds: f64) -> TestPipe {
    let sizes = pipewave::synth::sizes(material);
    let sz = sizes[rng.gen_range(0..sizes.len())];
    let (_, e_r, nu_r, rho_r) =
        pipewave::synth::SOILS[rng.gen_range(0..pipewave::synth::SOILS.len())];
    let e = (e_r.0.ln() + rng.gen::<f64>() * (e_r.1 / e_r.0).ln()).exp();
    let soil = Soil::new(
        e,
        rng.gen_range(nu_r.0..nu_r.1),
        rng.gen_range(rho_r.0..rho_r.1).round(),
        0.0,
    )
    .unwrap();
    let sys = System::new(
        Fluid::water(),
        pipewave::synth::pipe_of(material, &sz),
        soil,
        rng.gen_range(0.0..1.0),
        Model::Full,
        ContactMode::Reciprocal,
    )
    .unwrap();
    let positions = seed_layout(rng, sensor_range_m(material));
    let spec = RecordingSpec {
        sample_rate: 8000,
        seconds,
        positions_m: positions.clone(),
        noise_fraction: 0.3,
        seed: rng.gen(),
    };
    let rec = hydrant_test(&sys, &spec).unwrap();
    TestPipe {
        id: id.to_string(),
        material,
        od_mm: sz.od_mm,
        wall_mm: sz.wall_mm,
        soil,
        positions,
        rec,
    }
}

fn wav(dir: &Path, name: &str, rec: &HydrantRecording, format: WavFormat, gain: f64) {
    let ch: Vec<&[f64]> = rec.channels.iter().map(Vec::as_slice).collect();
    write_wav(&dir.join(name), rec.sample_rate, &ch, format, gain).unwrap();
}

fn gain(rec: &HydrantRecording) -> f64 {
    pipewave::synth::recordings::headroom_gain(&rec.channels)
}

/// A measurements row read back.
#[derive(Debug)]
struct Row {
    id: String,
    f: f64,
    k: f64,
    ks: f64,
    a: f64,
    as_: f64,
    notes: String,
}

fn read_rows(path: &Path) -> Vec<Row> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().clone();
    assert_eq!(
        h.iter().collect::<Vec<_>>(),
        [
            "segment_id",
            "frequency_hz",
            "k_re_rad_per_m",
            "attenuation_np_per_m",
            "k_re_std",
            "attenuation_std",
            "campaign",
            "note",
        ]
    );
    r.records()
        .map(|x| {
            let x = x.unwrap();
            let p = |i: usize| x[i].parse::<f64>().unwrap();
            Row {
                id: x[0].to_string(),
                f: p(1),
                k: p(2),
                a: p(3),
                ks: p(4),
                as_: p(5),
                notes: x[7].to_string(),
            }
        })
        .collect()
}

fn layout_text(rows: &[(&str, &str, usize, f64)]) -> String {
    let mut s = String::from("segment_id,file,channel,position_m\n");
    for (id, f, c, x) in rows {
        s.push_str(&format!("{id},{f},{c},{x}\n"));
    }
    s
}

/// Issue 15's acceptance, and the fit of the measurements it produces.
#[test]
fn acceptance_on_fresh_synthetic_recordings_and_the_fit() {
    let mut rng = ChaCha8Rng::seed_from_u64(ACCEPTANCE_SEED);
    let materials = [
        Material::CastIron,
        Material::DuctileIron,
        Material::Steel,
        Material::Pvc,
        Material::Mdpe,
        Material::Hdpe,
    ];
    let pipes: Vec<TestPipe> = materials
        .iter()
        .enumerate()
        .map(|(i, &m)| make_pipe(&mut rng, &format!("R{}", i + 1), m, 30.0))
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The three sample formats of interface.md, in turn.
    let formats = [WavFormat::Pcm16, WavFormat::Pcm24, WavFormat::Float32];
    let mut rows = Vec::new();
    for (i, p) in pipes.iter().enumerate() {
        let name = format!("{}.wav", p.id);
        wav(dir, &name, &p.rec, formats[i % 3], gain(&p.rec));
        for (c, &x) in p.positions.iter().enumerate() {
            rows.push((p.id.clone(), name.clone(), c, x));
        }
    }
    let rows_ref: Vec<(&str, &str, usize, f64)> = rows
        .iter()
        .map(|r| (r.0.as_str(), r.1.as_str(), r.2, r.3))
        .collect();
    std::fs::write(dir.join("layout.csv"), layout_text(&rows_ref)).unwrap();
    let out = dir.join("measurements.csv");
    let o = run(&[
        "wavenumbers".as_ref(),
        "--layout".as_ref(),
        dir.join("layout.csv").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = read_rows(&out);
    let (mut n, mut in_k, mut in_a) = (0usize, 0usize, 0usize);
    let mut rel = Vec::new();
    for p in &pipes {
        let bands: Vec<&Row> = got.iter().filter(|r| r.id == p.id).collect();
        assert!(
            bands.len() >= 4,
            "{} ({:?}, sensors at {:?}): only {} usable bands",
            p.id,
            p.material,
            p.positions,
            bands.len()
        );
        for b in bands {
            let k = p.rec.truth.at(b.f).expect("band inside the source band");
            n += 1;
            in_k += usize::from((b.k - k.re).abs() <= 2.0 * b.ks);
            in_a += usize::from((b.a + k.im).abs() <= 2.0 * b.as_);
            rel.push(((b.k - k.re) / k.re).abs());
            assert!(b.ks > 0.0 && b.as_ > 0.0 && b.a >= 0.0, "{b:?}");
        }
    }
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    let (ck, ca) = (in_k as f64 / n as f64, in_a as f64 / n as f64);
    eprintln!(
        "acceptance: {n} bands; truth inside 2 sigma: k_re {:.1} %, attenuation {:.1} %; k_re median error {:.3} %",
        100.0 * ck,
        100.0 * ca,
        100.0 * median
    );
    assert!(
        ck >= 0.90,
        "k_re inside 2 sigma for {:.1} % of bands",
        100.0 * ck
    );
    assert!(
        ca >= 0.85,
        "attenuation inside 2 sigma for {:.1} % of bands",
        100.0 * ca
    );
    assert!(median <= 0.005, "k_re median error {:.3} %", 100.0 * median);

    // The measurements calibrate without a failed fit.
    let mut seg = String::from(
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n",
    );
    for p in &pipes {
        seg.push_str(&format!(
            "{},{},{},{},{}\n",
            p.id,
            p.material.code(),
            p.od_mm,
            p.wall_mm,
            p.soil.density
        ));
    }
    std::fs::write(dir.join("segments.csv"), seg).unwrap();
    let fits = dir.join("fits.csv");
    let o = run(&[
        "fit".as_ref(),
        "--jobs".as_ref(),
        "2".as_ref(),
        "--segments".as_ref(),
        dir.join("segments.csv").as_os_str(),
        "--measurements".as_ref(),
        out.as_os_str(),
        "--out".as_ref(),
        fits.as_os_str(),
    ]);
    assert!(
        o.status.success(),
        "fit failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let mut r = csv::Reader::from_path(&fits).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name);
    let (i_st, i_e, i_nu) = (
        col("status").unwrap(),
        col("soil_youngs_modulus_pa").unwrap(),
        col("soil_poisson").unwrap(),
    );
    let (i_cp, i_cps) = (
        col("soil_p_wave_speed_m_per_s"),
        col("soil_p_wave_speed_std_m_per_s"),
    );
    let (mut metal, mut cp_in) = (0, 0);
    for rec in r.records() {
        let rec = rec.unwrap();
        let p = pipes.iter().find(|p| p.id == rec[0]).unwrap();
        assert_ne!(&rec[i_st], "failed", "{}: failed fit", p.id);
        let (cp_true, _) = p.soil.wave_speeds();
        let e: f64 = rec[i_e].parse().unwrap_or(f64::NAN);
        let nu: f64 = rec[i_nu].parse().unwrap_or(f64::NAN);
        let rho = p.soil.density;
        let cp_fit = (e * (1.0 - nu) / (rho * (1.0 + nu) * (1.0 - 2.0 * nu))).sqrt();
        eprintln!(
            "fit {} {:?}: status {}, E {:.3e} (true {:.3e}), nu {:.3} (true {:.3}), c_P from E, nu {:.0} m/s (true {:.0})",
            p.id, p.material, &rec[i_st], e, p.soil.youngs_modulus, nu, p.soil.poisson, cp_fit, cp_true
        );
        if let (Some(i), Some(j), false) = (i_cp, i_cps, p.material.is_plastic()) {
            let (cp, s): (f64, f64) = (rec[i].parse().unwrap(), rec[j].parse().unwrap());
            metal += 1;
            eprintln!("  {}: c_P {cp:.0} ± {s:.1} m/s (true {cp_true:.0})", p.id);
            cp_in += usize::from((cp - cp_true).abs() <= 2.0 * s);
        }
    }
    if metal > 0 {
        eprintln!("c_P inside 2 sigma for {cp_in} of {metal} metal pipes");
    } else {
        eprintln!("c_P coverage: the fit output has no soil_p_wave_speed columns in this build");
    }
}

/// The ductile-iron pipe (second size) in a loam of the recording tests.
fn ductile_iron_in_loam() -> System {
    System::new(
        Fluid::water(),
        pipewave::synth::pipe_of(
            Material::DuctileIron,
            &pipewave::synth::sizes(Material::DuctileIron)[1],
        ),
        Soil::new(5e7, 0.3, 1900.0, 0.0).unwrap(),
        0.5,
        Model::Full,
        ContactMode::Reciprocal,
    )
    .unwrap()
}

/// A small recording for the field-mistake tests: a ductile-iron pipe, sensors at 0, −25, +40 m.
fn small_recording() -> (HydrantRecording, Vec<f64>) {
    let sys = ductile_iron_in_loam();
    let positions = vec![0.0, -25.0, 40.0];
    let spec = RecordingSpec {
        sample_rate: 8000,
        seconds: 10.0,
        positions_m: positions.clone(),
        noise_fraction: 0.3,
        seed: 7,
    };
    (hydrant_test(&sys, &spec).unwrap(), positions)
}

/// Run `wavenumbers` on a layout text in `dir`; (exit code, stderr, output path).
fn wavenumbers(dir: &Path, layout: &str) -> (Option<i32>, String, PathBuf) {
    std::fs::write(dir.join("layout.csv"), layout).unwrap();
    let out = dir.join("m.csv");
    let o = run(&[
        "wavenumbers".as_ref(),
        "--layout".as_ref(),
        dir.join("layout.csv").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        out,
    )
}

fn mono(rec: &HydrantRecording, c: usize) -> HydrantRecording {
    HydrantRecording {
        sample_rate: rec.sample_rate,
        channels: vec![rec.channels[c].clone()],
        truth: rec.truth.clone(),
    }
}

#[test]
fn field_mistakes_get_messages_naming_file_line_and_what() {
    let (rec, _) = small_recording();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let g = gain(&rec);
    wav(dir, "ok.wav", &rec, WavFormat::Pcm16, g);
    // A good second segment in the same layout is still written when the first fails.
    let good = [
        ("G", "ok.wav", 0, 0.0),
        ("G", "ok.wav", 1, -25.0),
        ("G", "ok.wav", 2, 40.0),
    ];
    let with_good = |bad: &[(&str, &str, usize, f64)]| {
        let mut v = bad.to_vec();
        v.extend_from_slice(&good);
        layout_text(&v)
    };

    // Missing channel.
    let (code, err, out) = wavenumbers(
        dir,
        &with_good(&[
            ("A", "ok.wav", 0, 0.0),
            ("A", "ok.wav", 1, -25.0),
            ("A", "ok.wav", 3, 40.0),
        ]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("segment A: ")
            && err.contains("ok.wav (named in ")
            && err.contains("layout.csv line 4)")
            && err.contains("missing channel: column channel names channel 3 but the file has 3 channels (0 - 2)"),
        "{err}"
    );
    assert!(read_rows(&out).iter().all(|r| r.id == "G") && !read_rows(&out).is_empty());

    // A mono file where several channels are named.
    wav(dir, "mono.wav", &mono(&rec, 0), WavFormat::Pcm16, g);
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[
            ("A", "mono.wav", 0, 0.0),
            ("A", "mono.wav", 1, -25.0),
            ("A", "mono.wav", 2, 40.0),
        ]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("mono.wav (named in ")
            && err.contains("line 3)")
            && err.contains("the file is mono"),
        "{err}"
    );

    // A file at another sample rate than its partner.
    wav(dir, "m0.wav", &mono(&rec, 0), WavFormat::Pcm16, g);
    let mut fast = mono(&rec, 1);
    fast.sample_rate = 16_000;
    wav(dir, "m1.wav", &fast, WavFormat::Pcm16, g);
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[("A", "m0.wav", 0, 0.0), ("A", "m1.wav", 0, -25.0)]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("m1.wav (named in ")
            && err.contains("line 3)")
            && err.contains("sample rate 16000 Hz, but its partner m0.wav (line 2) is at 8000 Hz"),
        "{err}"
    );

    // Positions on the wrong side: the hydrant sensor and the +40 m sensor swapped.
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[
            ("A", "ok.wav", 0, 40.0),
            ("A", "ok.wav", 1, -25.0),
            ("A", "ok.wav", 2, 0.0),
        ]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("segment A (")
            && err.contains("positions on the wrong side or swapped: the sensor of line 3 (ok.wav channel 1, position -25.0 m) hears the source")
            && err.contains("before the sensor of line 4 (ok.wav channel 2, position 0 m), although it is stated farther"),
        "{err}"
    );

    // Zero distance: two sensors on one side at the same distance (a layout error: exit 2).
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[
            ("A", "ok.wav", 0, 0.0),
            ("A", "ok.wav", 1, 40.0),
            ("A", "ok.wav", 2, 40.0),
        ]),
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("layout.csv line 4, column position_m: segment A: zero distance"),
        "{err}"
    );

    // A clipped recording.
    wav(dir, "loud.wav", &rec, WavFormat::Pcm24, 6.0 * g);
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[
            ("A", "loud.wav", 0, 0.0),
            ("A", "loud.wav", 1, -25.0),
            ("A", "loud.wav", 2, 40.0),
        ]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("loud.wav (named in ")
            && err.contains("clipped recording: channel 0 has")
            && err.contains("full-scale samples"),
        "{err}"
    );

    // Not a WAV file at all, and a file that does not exist: messages, no panic.
    std::fs::write(dir.join("notes.wav"), "field notes, not audio").unwrap();
    let (code, err, _) = wavenumbers(
        dir,
        &layout_text(&[("A", "notes.wav", 0, 0.0), ("A", "gone.wav", 0, 20.0)]),
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("notes.wav (named in ") && err.contains("not a readable WAV file"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    // Bad cells of the layout: line and column named, exit 2.
    let (code, err, _) = wavenumbers(
        dir,
        "segment_id,file,channel,position_m\nA,ok.wav,one,0\nA,ok.wav,1,\n",
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("line 2, column channel: 'one'") && err.contains("line 3, column position_m"),
        "{err}"
    );
}

/// The noise-robust estimator: reference noise does not bias the attenuation (P77), while H1
/// (two channels) comes out high as model §10 says.
#[test]
fn three_channel_estimate_is_free_of_the_reference_noise_bias() {
    let (rec, positions) = small_recording();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    wav(dir, "r.wav", &rec, WavFormat::Float32, gain(&rec));
    let three: Vec<(&str, &str, usize, f64)> =
        (0..3).map(|c| ("A", "r.wav", c, positions[c])).collect();
    let (code, err, out) = wavenumbers(dir, &layout_text(&three));
    assert_eq!(code, Some(0), "{err}");
    let p77 = read_rows(&out);
    let (code, err, out) = wavenumbers(dir, &layout_text(&[three[0], three[2]]));
    assert_eq!(code, Some(0), "{err}");
    let h1 = read_rows(&out);
    assert!(h1
        .iter()
        .all(|r| r.notes.contains("h1_reference_noise_bias")));
    let truth: &TruthCurve = &rec.truth;
    let mean_ratio = |rows: &[Row]| {
        rows.iter()
            .map(|r| r.a / -truth.at(r.f).unwrap().im)
            .sum::<f64>()
            / rows.len() as f64
    };
    let (r77, r1) = (mean_ratio(&p77), mean_ratio(&h1));
    eprintln!("attenuation / truth: P77 {r77:.3}, H1 {r1:.3}");
    assert!((r77 - 1.0).abs() < 0.05, "P77 attenuation / truth {r77}");
    assert!(
        r1 > r77 + 0.03,
        "H1 {r1} should be biased high against P77 {r77}"
    );
}

/// sample_network/recordings is exactly what its README command writes, and gives usable
/// wavenumbers close to its truth file.
#[test]
fn sample_network_recordings_are_what_the_readme_makes_and_give_wavenumbers() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("sample_network");
    let readme = std::fs::read_to_string(sample.join("README.md")).unwrap();
    let line = readme
        .lines()
        .find(|l| l.contains("--recordings WM"))
        .expect("the README gives the recordings command");
    let command = line.trim().trim_matches('`');
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("net");
    let args: Vec<std::ffi::OsString> = command
        .split_whitespace()
        .skip(1)
        .map(|a| {
            if a == "sample_network" {
                out.clone().into_os_string()
            } else {
                a.into()
            }
        })
        .collect();
    let o = bin().args(&args).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        !out.join("segments.csv").exists(),
        "--recordings-only writes only the recordings"
    );
    for f in ["layout.csv", "WM10003.wav", "truth_wavenumbers.csv"] {
        assert!(
            std::fs::read(out.join("recordings").join(f)).unwrap()
                == std::fs::read(sample.join("recordings").join(f)).unwrap(),
            "sample_network/recordings/{f} differs from what `{command}` writes: regenerate it"
        );
    }
    let m = tmp.path().join("m.csv");
    let o = run(&[
        "wavenumbers".as_ref(),
        "--layout".as_ref(),
        sample.join("recordings/layout.csv").as_os_str(),
        "--out".as_ref(),
        m.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_rows(&m);
    assert!(rows.len() >= 4, "{} bands", rows.len());
    // The truth file, every 10 Hz, interpolated linearly.
    let mut r = csv::Reader::from_path(sample.join("recordings/truth_wavenumbers.csv")).unwrap();
    let truth: Vec<(f64, f64)> = r
        .records()
        .map(|x| {
            let x = x.unwrap();
            (x[1].parse().unwrap(), x[2].parse().unwrap())
        })
        .collect();
    let mut rel: Vec<f64> = rows
        .iter()
        .map(|b| {
            let i = truth.iter().rposition(|t| t.0 <= b.f).unwrap();
            let (f0, k0) = truth[i];
            let (f1, k1) = truth[i + 1];
            let k = k0 + (k1 - k0) * (b.f - f0) / (f1 - f0);
            ((b.k - k) / k).abs()
        })
        .collect();
    rel.sort_by(f64::total_cmp);
    assert!(
        rel[rel.len() / 2] < 0.005,
        "median k_re error {}",
        rel[rel.len() / 2]
    );
}

/// Sides that disagree (the pipe changes at the hydrant: a stiffer soil on the + side) are noted
/// `reflection_suspected`; the same test with one pipe on both sides is not.
#[test]
fn disagreeing_sides_are_noted() {
    let pipe = pipewave::synth::pipe_of(
        Material::DuctileIron,
        &pipewave::synth::sizes(Material::DuctileIron)[1],
    );
    let sys = |e: f64| {
        System::new(
            Fluid::water(),
            pipe,
            Soil::new(e, 0.3, 1900.0, 0.0).unwrap(),
            0.5,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap()
    };
    let spec = RecordingSpec {
        sample_rate: 8000,
        seconds: 10.0,
        positions_m: vec![0.0, -30.0, 30.0],
        noise_fraction: 0.3,
        seed: 11,
    };
    // The same seed gives the same source and noise: only the + side's pipe differs.
    let a = hydrant_test(&sys(3e7), &spec).unwrap();
    let b = hydrant_test(&sys(3e8), &spec).unwrap();
    assert_eq!(a.channels[0], b.channels[0]);
    let mixed = HydrantRecording {
        sample_rate: 8000,
        channels: vec![
            a.channels[0].clone(),
            a.channels[1].clone(),
            b.channels[2].clone(),
        ],
        truth: a.truth.clone(),
    };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let share = |rec: &HydrantRecording, name: &str| {
        wav(dir, name, rec, WavFormat::Float32, gain(rec));
        let rows: Vec<(&str, &str, usize, f64)> = (0..3)
            .map(|c| ("A", name, c, spec.positions_m[c]))
            .collect();
        let (code, err, out) = wavenumbers(dir, &layout_text(&rows));
        assert_eq!(code, Some(0), "{err}");
        let rows = read_rows(&out);
        let noted = rows
            .iter()
            .filter(|r| r.notes.contains("reflection_suspected"))
            .count();
        noted as f64 / rows.len() as f64
    };
    let (same, differ) = (share(&a, "same.wav"), share(&mixed, "mixed.wav"));
    eprintln!("bands noted reflection_suspected: one pipe {same:.2}, two pipes {differ:.2}");
    assert!(same < 0.05, "one pipe: {same}");
    assert!(differ > 0.5, "two pipes: {differ}");
}

/// The seed of the chain test: chosen when the test was written (after the estimator's bin
/// weighting was fixed on the example's seed 20261122); not changed since.
const CHAIN_SEED: u64 = 0x150c_2026;

/// Issue 15's last acceptance item on a small sample (the example
/// examples/wavenumbers_calibration.rs runs it on 100 pipes): recordings of metal pipes →
/// `wavenumbers` → import + calibrate, the fitted c_P against the truth. The fit is given only
/// the inventory and the measurements the recordings produced.
#[test]
fn recorded_metal_pipes_calibrate_and_give_c_p_within_its_errors() {
    use pipewave::synth::recordings::recovery::{run_chain, ChainSpec, Feed};
    let tmp = tempfile::tempdir().unwrap();
    let spec = ChainSpec {
        seed: CHAIN_SEED,
        metal_pipes: 12,
        seconds: 30.0,
        jobs: 2,
        feed: Feed::Recordings,
    };
    let r = run_chain(&spec, tmp.path()).unwrap();
    assert!(r.unusable.is_empty(), "{:?}", r.unusable);
    let mut z = Vec::new();
    let mut rel = Vec::new();
    for p in &r.pipes {
        let f = p.fit.as_ref().expect("every recorded pipe is fitted");
        let cp = f.soil_p_wave_speed_m_per_s.unwrap();
        eprintln!(
            "{} {:?}: {} bands, {}, c_P {cp:.1} ± {:.1} m/s (true {:.1}), z {:+.2}",
            p.segment_id,
            p.material,
            p.bands.len(),
            f.status.as_str(),
            f.soil_p_wave_speed_std_m_per_s.unwrap(),
            p.cp_true,
            p.cp_z()
        );
        assert!(
            p.bands.len() >= 4,
            "{}: {} bands",
            p.segment_id,
            p.bands.len()
        );
        z.push(p.cp_z());
        rel.push((cp / p.cp_true - 1.0).abs());
    }
    let rec = &r.recovery;
    assert_eq!((rec.n_fitted, rec.n_failed, r.failed()), (12, 0, 0));
    assert_eq!(rec.n_judged, 12);
    let mean_z = z.iter().sum::<f64>() / z.len() as f64;
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    eprintln!(
        "c_P inside 2 sigma for {} of 12; mean z {mean_z:+.2}; median |error| {:.2} %",
        rec.inside[0],
        100.0 * median
    );
    // 12 pipes at 95 %: 10 or more inside with probability 98 %.
    assert!(
        rec.inside[0] >= 10,
        "c_P inside 2 sigma for {} of 12",
        rec.inside[0]
    );
    // No bias: the mean of 12 unit-variance z is within ±0.6 (1.7 of its standard errors);
    // the chain before the neighbour-only bin weights gave −0.79 on 40 pipes.
    assert!(mean_z.abs() <= 0.6, "mean c_P z {mean_z:+.2}");
    assert!(
        median <= 0.015,
        "median |c_P error| {:.2} %",
        100.0 * median
    );
}

/// The measurements `wavenumbers` writes for a segment id a spreadsheet would read as a formula
/// (written `'+W3`, issue 17) import as that id: the import reads a `'` before a formula lead as
/// a spreadsheet does.
#[test]
fn measurements_of_a_formula_like_id_import_as_that_id() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::copy(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/sample_network/recordings/WM10003.wav"
        ),
        dir.join("WM10003.wav"),
    )
    .unwrap();
    let (code, err, out) = wavenumbers(
        dir,
        &layout_text(&[
            ("+W3", "WM10003.wav", 0, 0.0),
            ("+W3", "WM10003.wav", 1, -70.5),
            ("+W3", "WM10003.wav", 2, 59.7),
        ]),
    );
    assert_eq!(code, Some(0), "{err}");
    let text = std::fs::read_to_string(&out).unwrap();
    let rows = text.lines().count() - 1;
    assert!(rows >= 4 && text.contains("\"'+W3\""), "{text}");
    std::fs::write(
        dir.join("segments.csv"),
        "segment_id,material,outer_diameter_mm,wall_thickness_mm,soil_density_kg_m3\n\
         +W3,DI,326,7.2,1884\n",
    )
    .unwrap();
    let db = dir.join("x.sqlite");
    let o = run(&[
        "import".as_ref(),
        "--db".as_ref(),
        db.as_os_str(),
        "--segments".as_ref(),
        dir.join("segments.csv").as_os_str(),
        "--measurements".as_ref(),
        out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let database = pipewave::db::Database::open(&db).unwrap();
    let m = pipewave::db::inventory::load_measurements(database.conn(), "+W3").unwrap();
    assert_eq!(m.len(), rows);
}

/// The bins' weights and selection do not depend on their own noise (estimate.rs,
/// `VARIANCE_SMOOTHING_BINS`): in the top bands of a pipe, where the coherence falls towards
/// `--min-coherence`, the attenuation is not biased low. Twenty recordings of one ductile-iron
/// pipe with different noise; the mean attenuation z of each recording's top five bands. With
/// weights and selection from each bin's own spectra it was −0.47 (200 bands of 40 metal pipes,
/// examples/wavenumbers_calibration.rs); its standard error here is 1/√100 = 0.1.
#[test]
fn attenuation_is_not_biased_low_where_the_coherence_falls() {
    use pipewave::recordings::estimate::analyse_audio;
    use pipewave::recordings::wav::SegmentAudio;
    use pipewave::recordings::{EstimateOptions, SegmentLayout};
    let sys = ductile_iron_in_loam();
    let positions = vec![0.0, -45.0, 70.0];
    let seg = SegmentLayout::one_file("B", "b.wav", &positions);
    let (mut z, mut n) = (0.0, 0usize);
    for seed in 0..20u64 {
        let spec = RecordingSpec {
            sample_rate: 8000,
            seconds: 30.0,
            positions_m: positions.clone(),
            noise_fraction: 0.3,
            seed: 0x15_0000 + seed,
        };
        let rec = hydrant_test(&sys, &spec).unwrap();
        let audio = SegmentAudio {
            sample_rate: 8000,
            channels: rec.channels.clone(),
        };
        let r = analyse_audio(
            Path::new("layout.csv"),
            &seg,
            &audio,
            &EstimateOptions::default(),
            &|_| {},
        )
        .unwrap();
        for b in r.bands.iter().rev().take(5) {
            let k = rec.truth.at(b.frequency_hz).unwrap();
            z += (b.attenuation + k.im) / b.attenuation_std;
            n += 1;
        }
    }
    let mean = z / n as f64;
    eprintln!("mean attenuation z of the top five bands: {mean:+.3} ({n} bands)");
    assert_eq!(n, 100);
    assert!(
        mean > -0.25,
        "attenuation biased low at the top: mean z {mean:+.3}"
    );
}
