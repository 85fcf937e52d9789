//! Acceptance figures of the network soil field (model §7.12) on fresh synthetic networks
//! with geological units (`synth --units`).
//!
//! `cargo run --release --example field_acceptance -- baseline [NETWORKS] [SEGMENTS] [SEED]`
//! (default 20 600 380001): how hard the generator is, without any fit. For every network at
//! correlation lengths 100, 350 and 1000 m: the leak-band speed error of the table (the
//! same pipe in the table soil E_m 5e7 Pa, ν_m 0.33, ξ 0.5), of each unit's mean soil with
//! ξ 0.5, and of the true soil with ξ 0.5, for plastic and metal pipes.
//!
//! `cargo build --release && cargo run --release --example field_acceptance -- grid [NETWORKS]
//! [SEGMENTS] [SEED] [JOBS] [CELLS]` (default 5 600 390001 2, all cells; CELLS such as
//! `15:350,15:1000` runs only those): measured fraction 5, 15, 30 % ×
//! correlation length 100, 350, 1000 m, 10 % wrong labels, NETWORKS fresh networks per cell.
//! Each network is written, imported and calibrated by the `pipewave` binary beside this
//! example (target/release/pipewave); for the segments without measurements the predictions
//! are compared with the truth: plastic median / p90 and metal p90 of |leak-band speed error|,
//! the share of truths within 2σ, the median 2σ width, the share with a speed and an error,
//! the table's errors on the same segments, and the leave-one-out z (P82) of the measured.
//!
//! `cargo run --release --example field_acceptance -- zones [NETWORKS] [SEGMENTS] [SEED] [JOBS]
//! [FRACTION] [ZONES]` (default 10 600 640001 1 0.15 16): zoned networks (`synth --zones 16`, no
//! units), the segments without measurements against the truth, per network and pooled. With
//! ZONES 0, `synth`'s plain networks: each segment's soil class drawn on its own, its label
//! right, so the labels are not contiguous. The environment
//! variable `PIPEWAVE_BIN` names another `pipewave` binary to import and calibrate with (e.g. an
//! older build, for a before/after comparison); every mode honours it.
//!
//! `cargo run --release --example field_acceptance -- plan [NETWORKS] [SEGMENTS] [SEED] [JOBS]`
//! (default 3 600 395001 2): on networks at 15 % measured and 350 m, the plastic p90 error of
//! the originally unmeasured segments after importing the later-campaign measurements of
//! `plan`'s 30 picks and recalibrating, against the mean over 20 random draws of 30.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use pipewave::field::model::{Hyper, Sym2};
use pipewave::invert::assemble::leak_band_speed_of;
use pipewave::physics::{Fluid, Soil, System};
use pipewave::synth::field::moduli;
use pipewave::synth::network::recovery::quantile;
use pipewave::synth::network::NetworkTables;
use pipewave::synth::{generate, geology, pipe_of, SynthOptions, SynthSegment, TABLE_CONTACT};

/// Correlation lengths of the grid, m.
const CORRELATION_LENGTHS_M: [f64; 3] = [100.0, 350.0, 1000.0];
/// Geological units of every network.
const UNITS: usize = 3;

/// Median and p90 of |x| in per cent, with the count.
fn med_p90(errors: &[f64]) -> String {
    let mut v: Vec<f64> = errors.iter().map(|e| 100.0 * e.abs()).collect();
    v.sort_by(f64::total_cmp);
    format!(
        "median {:5.2} % p90 {:5.2} % (n {})",
        quantile(&v, 0.5),
        quantile(&v, 0.9),
        v.len()
    )
}

/// The options of network `seed` of a cell.
fn options(segments: usize, seed: u64, ell: f64, measured: f64) -> SynthOptions {
    SynthOptions {
        segments,
        seed,
        defect_fraction: 0.0,
        units: UNITS,
        correlation_length_m: ell,
        measured_fraction: measured,
        wrong_label_fraction: 0.1,
        ..SynthOptions::default()
    }
}

/// Leak-band speed of a segment's pipe in soil (E, ν) at its own density, contact ξ 0.5.
fn speed_in(s: &SynthSegment, opts: &SynthOptions, e: f64, nu: f64) -> Option<f64> {
    let soil = Soil::new(e, nu, s.soil_density, 0.0).ok()?;
    let sys = System::new(
        Fluid::water(),
        pipe_of(s.material, &s.size),
        soil,
        TABLE_CONTACT,
        opts.model,
        opts.contact_mode,
    )
    .ok()?;
    leak_band_speed_of(&sys)
}

/// Relative errors of the table, unit-mean and true-soil speeds, by [plastic, metal].
#[derive(Default)]
struct Baseline {
    table: [Vec<f64>; 2],
    unit_mean: [Vec<f64>; 2],
    true_soil: [Vec<f64>; 2],
}

fn baseline(networks: u64, segments: usize, seed0: u64) {
    println!(
        "baseline: {networks} networks of {segments} segments per correlation length, \
         {UNITS} units, seeds from {seed0}"
    );
    let mut all = Baseline::default();
    for (c, &ell) in CORRELATION_LENGTHS_M.iter().enumerate() {
        let mut b = Baseline::default();
        for n in 0..networks {
            let opts = options(segments, seed0 + 1000 * c as u64 + n, ell, 1.0);
            let geo = geology(&opts).expect("units");
            for s in generate(&opts) {
                let Some(truth) = s.leak_band_speed else {
                    continue;
                };
                let k = usize::from(!s.material.is_plastic());
                if let Some(t) = s.table_leak_band_speed {
                    b.table[k].push(t / truth - 1.0);
                }
                let unit = geo.units[s.unit.expect("unit")];
                let (e, nu) = moduli(unit.mean[0].exp(), unit.mean[1].exp(), s.soil_density);
                if let Some(v) = speed_in(&s, &opts, e, nu) {
                    b.unit_mean[k].push(v / truth - 1.0);
                }
                if let Some(v) = speed_in(&s, &opts, s.soil_modulus, s.soil_poisson) {
                    b.true_soil[k].push(v / truth - 1.0);
                }
            }
        }
        println!("correlation length {ell} m:");
        report_baseline(&b);
        for k in 0..2 {
            all.table[k].extend(&b.table[k]);
            all.unit_mean[k].extend(&b.unit_mean[k]);
            all.true_soil[k].extend(&b.true_soil[k]);
        }
    }
    println!("all:");
    report_baseline(&all);
}

fn report_baseline(b: &Baseline) {
    for (k, name) in ["plastic", "metal"].iter().enumerate() {
        println!("  {name:7} table     {}", med_p90(&b.table[k]));
        println!("  {name:7} unit mean {}", med_p90(&b.unit_mean[k]));
        println!("  {name:7} true soil {}", med_p90(&b.true_soil[k]));
    }
}

/// The `pipewave` binary built beside this example.
fn binary() -> PathBuf {
    if let Some(bin) = std::env::var_os("PIPEWAVE_BIN") {
        return PathBuf::from(bin);
    }
    let exe = std::env::current_exe().expect("own path");
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join("pipewave"))
        .expect("target directory");
    if !bin.exists() {
        eprintln!(
            "{} not found: run `cargo build --release` first",
            bin.display()
        );
        std::process::exit(2);
    }
    bin
}

/// Run `pipewave ARGS`; exit with its message if it fails.
fn pipewave(args: &[&str]) {
    let out = Command::new(binary())
        .args(args)
        .output()
        .expect("pipewave runs");
    if !out.status.success() {
        eprintln!(
            "pipewave {} failed:\n{}{}",
            args.join(" "),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        std::process::exit(1);
    }
}

/// A synthetic network written, imported and calibrated in `dir`.
struct Network {
    segments: Vec<SynthSegment>,
    dir: PathBuf,
    db: PathBuf,
}

impl Network {
    fn build(opts: &SynthOptions, dir: PathBuf, jobs: usize) -> Network {
        let _ = std::fs::remove_dir_all(&dir);
        let segments = generate(opts);
        NetworkTables::from_synth(&segments, opts.srid)
            .write_dir(&dir)
            .expect("network written");
        let db = dir.join("network.sqlite");
        let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
        pipewave(&[
            "import",
            "--db",
            &s(&db),
            "--segments",
            &s(&dir.join("segments.csv")),
            "--measurements",
            &s(&dir.join("measurements.csv")),
        ]);
        let net = Network { segments, dir, db };
        net.calibrate(&net.db, jobs);
        net
    }

    fn calibrate(&self, db: &Path, jobs: usize) {
        pipewave(&[
            "calibrate",
            "--db",
            db.to_str().expect("utf-8 path"),
            "--jobs",
            &jobs.to_string(),
        ]);
    }

    /// Import the later-campaign measurements of `ids` into `db` and recalibrate.
    fn measure(&self, db: &Path, ids: &[String], jobs: usize) {
        let picked: Vec<SynthSegment> = self
            .segments
            .iter()
            .filter(|s| ids.contains(&s.id))
            .cloned()
            .collect();
        let file = self.dir.join("later.csv");
        std::fs::write(
            &file,
            NetworkTables::campaign(&picked, "later").measurements_csv(),
        )
        .expect("campaign written");
        pipewave(&[
            "import",
            "--db",
            db.to_str().expect("utf-8 path"),
            "--measurements",
            file.to_str().expect("utf-8 path"),
        ]);
        self.calibrate(db, jobs);
    }
}

/// A segment's speed and its one-sigma error, m/s.
type Speed = (Option<f64>, Option<f64>);

/// The predictions, and the latest fits' leak-band speeds, of a database by segment.
fn speeds(db: &Path) -> (HashMap<String, Speed>, HashMap<String, Speed>) {
    let conn = rusqlite::Connection::open(db).expect("database opens");
    let read = |sql: &str| -> HashMap<String, Speed> {
        let mut st = conn.prepare(sql).expect("query");
        st.query_map([], |r| Ok((r.get(0)?, (r.get(1)?, r.get(2)?))))
            .expect("rows")
            .collect::<Result<_, _>>()
            .expect("rows")
    };
    (
        read("SELECT segment_id, leak_band_speed_m_per_s, leak_band_speed_std_m_per_s FROM predictions"),
        read("SELECT segment_id, leak_band_speed_m_per_s, leak_band_speed_std_m_per_s FROM latest_fits"),
    )
}

/// The leave-one-out z (P82) of the measured segments, if the database has them.
fn loo_z(db: &Path) -> Option<Vec<f64>> {
    let conn = rusqlite::Connection::open(db).expect("database opens");
    let mut st = conn
        .prepare("SELECT loo_z FROM field_segments WHERE loo_z IS NOT NULL")
        .ok()?;
    let z = st
        .query_map([], |r| r.get::<_, f64>(0))
        .ok()?
        .collect::<Result<Vec<f64>, _>>()
        .ok()?;
    Some(z)
}

/// Figures of one grid cell, pooled over its networks (segments without measurements).
#[derive(Default)]
struct Cell {
    /// Relative errors of the predicted leak-band speed: [plastic, metal].
    error: [Vec<f64>; 2],
    /// The table's relative errors on the same segments.
    table: [Vec<f64>; 2],
    /// 2σ / ĉ of each prediction.
    width: [Vec<f64>; 2],
    /// Plastic segments: (true class, label wrong, signed error, z of the truth = error / σ).
    plastic: Vec<(&'static str, bool, f64, f64)>,
    covered: usize,
    with_speed: usize,
    unmeasured: usize,
    z: Vec<f64>,
}

impl Cell {
    fn add(&mut self, net: &Network) {
        let (pred, _) = speeds(&net.db);
        for s in net.segments.iter().filter(|s| !s.measured) {
            let Some(truth) = s.leak_band_speed else {
                continue;
            };
            self.unmeasured += 1;
            let k = usize::from(!s.material.is_plastic());
            if let Some(t) = s.table_leak_band_speed {
                self.table[k].push(t / truth - 1.0);
            }
            let Some(&(Some(c), Some(sd))) = pred.get(&s.id) else {
                continue;
            };
            if !(c.is_finite() && sd.is_finite()) {
                continue;
            }
            self.with_speed += 1;
            self.error[k].push(c / truth - 1.0);
            if k == 0 {
                self.plastic.push((
                    s.soil_type,
                    s.soil_label != s.soil_type,
                    c / truth - 1.0,
                    (c - truth) / sd,
                ));
            }
            self.width[k].push(2.0 * sd / c);
            if (c - truth).abs() <= 2.0 * sd {
                self.covered += 1;
            }
        }
        if let Some(z) = loo_z(&net.db) {
            self.z.extend(z);
        }
    }

    fn report(&self, label: &str) {
        let pct = |v: &[f64], p: f64| {
            let mut a: Vec<f64> = v.iter().map(|x| 100.0 * x.abs()).collect();
            a.sort_by(f64::total_cmp);
            quantile(&a, p)
        };
        let n = self.with_speed.max(1) as f64;
        let z_std = if self.z.len() > 1 {
            let m = self.z.iter().sum::<f64>() / self.z.len() as f64;
            let v = self.z.iter().map(|z| (z - m).powi(2)).sum::<f64>() / (self.z.len() - 1) as f64;
            format!("{:.2} (n {})", v.sqrt(), self.z.len())
        } else {
            "n/a".into()
        };
        println!(
            "{label}: plastic {:.2} / {:.2} % (table {:.2} / {:.2} %), metal p90 {:.3} % (table \
             {:.3} %), within 2σ {:.1} %, median 2σ width plastic {:.2} % metal {:.3} %, with \
             speed {}/{}, LOO z std {z_std}",
            pct(&self.error[0], 0.5),
            pct(&self.error[0], 0.9),
            pct(&self.table[0], 0.5),
            pct(&self.table[0], 0.9),
            pct(&self.error[1], 0.9),
            pct(&self.table[1], 0.9),
            100.0 * self.covered as f64 / n,
            pct(&self.width[0], 0.5),
            pct(&self.width[1], 0.5),
            self.with_speed,
            self.unmeasured,
        );
    }

    /// The plastic errors by true soil class and by label (signed median shows a bias), and
    /// the spread of (ĉ − c)/σ against the truth.
    fn breakdown(&self) {
        let show = |name: &str, rows: Vec<&(&str, bool, f64, f64)>| {
            let mut abs: Vec<f64> = rows.iter().map(|r| 100.0 * r.2.abs()).collect();
            let mut signed: Vec<f64> = rows.iter().map(|r| 100.0 * r.2).collect();
            abs.sort_by(f64::total_cmp);
            signed.sort_by(f64::total_cmp);
            let z: Vec<f64> = rows.iter().map(|r| r.3).collect();
            let zsd = (z.iter().map(|v| v * v).sum::<f64>() / z.len().max(1) as f64).sqrt();
            println!(
                "    plastic {name:18} n {:4}: |error| median {:.2} % p90 {:.2} %, signed median                  {:+.2} %, rms (ĉ − c)/σ {:.2}",
                rows.len(),
                quantile(&abs, 0.5),
                quantile(&abs, 0.9),
                quantile(&signed, 0.5),
                zsd
            );
        };
        let mut classes: Vec<&str> = self.plastic.iter().map(|r| r.0).collect();
        classes.sort_unstable();
        classes.dedup();
        for c in classes {
            show(c, self.plastic.iter().filter(|r| r.0 == c).collect());
        }
        show(
            "label right",
            self.plastic.iter().filter(|r| !r.1).collect(),
        );
        show("label wrong", self.plastic.iter().filter(|r| r.1).collect());
    }
}

/// Measured fractions of the grid.
const MEASURED_FRACTIONS: [f64; 3] = [0.05, 0.15, 0.30];

/// Whether cell (measured fraction, ℓ) is among `cells` ("15:350,15:1000"; empty: all).
fn selected(cells: &str, frac: f64, ell: f64) -> bool {
    cells.is_empty()
        || cells
            .split(',')
            .any(|c| c == format!("{:.0}:{:.0}", 100.0 * frac, ell))
}

fn grid(networks: u64, segments: usize, seed0: u64, jobs: usize, cells: &str) {
    println!(
        "grid: {networks} networks of {segments} segments per cell, {UNITS} units, 10 % wrong \
         labels, seeds from {seed0}; errors as median / p90 of |ĉ/c − 1|"
    );
    let root =
        std::env::temp_dir().join(format!("pipewave-field-acceptance-{}", std::process::id()));
    let mut all = Cell::default();
    for (a, &frac) in MEASURED_FRACTIONS.iter().enumerate() {
        for (b, &ell) in CORRELATION_LENGTHS_M.iter().enumerate() {
            if !selected(cells, frac, ell) {
                continue;
            }
            let mut cell = Cell::default();
            for n in 0..networks {
                let seed = seed0 + 100 * (3 * a + b) as u64 + n;
                let opts = options(segments, seed, ell, frac);
                let net = Network::build(&opts, root.join(format!("n{seed}")), jobs);
                cell.add(&net);
                let _ = std::fs::remove_dir_all(&net.dir);
            }
            cell.report(&format!("measured {:2.0} % ℓ {:4} m", 100.0 * frac, ell));
            cell.breakdown();
            for k in 0..2 {
                all.error[k].extend(&cell.error[k]);
                all.table[k].extend(&cell.table[k]);
                all.width[k].extend(&cell.width[k]);
            }
            all.covered += cell.covered;
            all.with_speed += cell.with_speed;
            all.unmeasured += cell.unmeasured;
            all.z.extend(&cell.z);
        }
    }
    all.report("all cells");
    let _ = std::fs::remove_dir_all(&root);
}

/// Zoned networks (`synth --zones`: each zone one soil with a per-segment scatter, no
/// correlated field, no wrong labels), or with `zones` 0 plain ones (each segment's class on
/// its own), at measured fraction `frac`: the predictions of the segments without
/// measurements against the truth, pooled over the networks.
fn zones_check(networks: u64, segments: usize, seed0: u64, jobs: usize, frac: f64, zones: usize) {
    println!(
        "zones: {networks} networks of {segments} segments in {zones} zones, measured \
         {:.0} %, seeds from {seed0}; errors as median / p90 of |ĉ/c − 1|",
        100.0 * frac
    );
    let root = std::env::temp_dir().join(format!("pipewave-field-zones-{}", std::process::id()));
    let mut cell = Cell::default();
    for n in 0..networks {
        let seed = seed0 + n;
        let opts = SynthOptions {
            segments,
            seed,
            defect_fraction: 0.0,
            zones,
            measured_fraction: frac,
            ..SynthOptions::default()
        };
        let net = Network::build(&opts, root.join(format!("n{seed}")), jobs);
        let mut one = Cell::default();
        one.add(&net);
        one.report(&format!("  network {seed}"));
        cell.add(&net);
        let _ = std::fs::remove_dir_all(&net.dir);
    }
    cell.report(&format!("measured {:2.0} %, {zones} zones", 100.0 * frac));
    let _ = std::fs::remove_dir_all(&root);
}

/// Plastic p90 |error| in per cent over the plastic segments of `ids`, each with its fitted
/// speed if it has a fit, else its prediction (a segment with neither counts as the table).
fn plastic_p90(net: &Network, db: &Path, ids: &[&SynthSegment]) -> f64 {
    let (pred, fits) = speeds(db);
    let mut e: Vec<f64> = ids
        .iter()
        .filter(|s| s.material.is_plastic())
        .filter_map(|s| {
            let truth = s.leak_band_speed?;
            let c = fits
                .get(&s.id)
                .and_then(|f| f.0)
                .or_else(|| pred.get(&s.id).and_then(|p| p.0))
                .or(s.table_leak_band_speed)?;
            Some(100.0 * (c / truth - 1.0).abs())
        })
        .collect();
    e.sort_by(f64::total_cmp);
    let _ = net;
    quantile(&e, 0.9)
}

/// A consistent copy of a database (VACUUM INTO).
fn copy_db(from: &Path, to: &Path) {
    let _ = std::fs::remove_file(to);
    let conn = rusqlite::Connection::open(from).expect("database opens");
    conn.execute("VACUUM INTO ?1", [to.to_str().expect("utf-8 path")])
        .expect("database copied");
}

fn plan_check(networks: u64, segments: usize, seed0: u64, jobs: usize) {
    use rand::{seq::SliceRandom, SeedableRng};
    const PICKS: usize = 30;
    const DRAWS: u64 = 20;
    println!(
        "plan: {networks} networks of {segments} segments, 15 % measured, ℓ 350 m; {PICKS} \
         picks against {DRAWS} random draws of {PICKS}"
    );
    let root = std::env::temp_dir().join(format!("pipewave-field-plan-{}", std::process::id()));
    let mut wins = 0;
    for n in 0..networks {
        let seed = seed0 + n;
        let net = Network::build(
            &options(segments, seed, 350.0, 0.15),
            root.join(format!("n{seed}")),
            jobs,
        );
        let unmeasured: Vec<&SynthSegment> = net.segments.iter().filter(|s| !s.measured).collect();
        let before = plastic_p90(&net, &net.db, &unmeasured);
        let base = net.dir.join("base.sqlite");
        copy_db(&net.db, &base);
        let next = net.dir.join("next.csv");
        pipewave(&[
            "plan",
            "--db",
            net.db.to_str().expect("utf-8 path"),
            "--count",
            &PICKS.to_string(),
            "--out",
            next.to_str().expect("utf-8 path"),
        ]);
        let picks: Vec<String> = csv::Reader::from_path(&next)
            .expect("plan written")
            .records()
            .map(|r| r.expect("row")[0].to_string())
            .collect();
        let work = net.dir.join("work.sqlite");
        copy_db(&base, &work);
        net.measure(&work, &picks, jobs);
        let planned = plastic_p90(&net, &work, &unmeasured);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut random = Vec::new();
        for _ in 0..DRAWS {
            let ids: Vec<String> = unmeasured
                .choose_multiple(&mut rng, PICKS)
                .map(|s| s.id.clone())
                .collect();
            copy_db(&base, &work);
            net.measure(&work, &ids, jobs);
            random.push(plastic_p90(&net, &work, &unmeasured));
        }
        let mean = random.iter().sum::<f64>() / random.len() as f64;
        let plastic_picks = net
            .segments
            .iter()
            .filter(|s| picks.contains(&s.id) && s.material.is_plastic())
            .count();
        let win = before - planned > before - mean;
        wins += usize::from(win);
        println!(
            "network {seed}: plastic p90 {before:.2} % before; after plan's picks {planned:.2} % \
             ({plastic_picks} of {PICKS} plastic); after random draws mean {mean:.2} % (range \
             {:.2} - {:.2} %); plan better: {win}",
            random.iter().copied().fold(f64::INFINITY, f64::min),
            random.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        );
        let _ = std::fs::remove_dir_all(&net.dir);
    }
    println!("plan better than the random mean on {wins} of {networks} networks");
    let _ = std::fs::remove_dir_all(&root);
}

/// The generator's hyper-parameters θ of P78 at correlation length `ell`: B from the unit
/// spreads and their correlation, T the per-pipe scatter (correlated as the field).
fn true_hyper(ell: f64) -> Hyper {
    use pipewave::synth::field::{
        PIPE_SCATTER_LN, UNIT_SPREAD_CORRELATION, UNIT_SPREAD_LN_CP, UNIT_SPREAD_LN_CS,
    };
    let (p, s, r) = (
        UNIT_SPREAD_LN_CP,
        UNIT_SPREAD_LN_CS,
        UNIT_SPREAD_CORRELATION,
    );
    let t = PIPE_SCATTER_LN * PIPE_SCATTER_LN;
    Hyper {
        b: Sym2::new(p * p, r * p * s, s * s),
        ell,
        t: Sym2::new(t, r * t, t),
    }
}

/// Plastic relative errors of one rung of the oracle ladder: all, and in the stiffest unit.
#[derive(Default)]
struct Rung {
    /// (u_true − m*)_S / √S*_SS of the posterior of ln c_S.
    zu: Vec<f64>,
    all: Vec<f64>,
    stiff: Vec<f64>,
    covered: usize,
}

impl Rung {
    fn push(&mut self, e: f64, stiff: bool, covered: bool) {
        self.all.push(e);
        if stiff {
            self.stiff.push(e);
        }
        self.covered += usize::from(covered);
    }

    fn report(&self, name: &str) {
        let rms = (self.zu.iter().map(|z| z * z).sum::<f64>() / self.zu.len().max(1) as f64).sqrt();
        println!(
            "  {name:46} plastic {}; stiffest unit {}; within 2σ {:.1} %; rms z(ln c_S) {rms:.2}",
            med_p90(&self.all),
            med_p90(&self.stiff),
            100.0 * self.covered as f64 / self.all.len().max(1) as f64
        );
    }
}

/// The oracle ladder of the judged cells: where the plastic p90 of the unmeasured segments is
/// lost. Every rung predicts from the same measured segments' stored fits (û, I):
/// (a) the generator's θ, true labels and the true unit means; (a′) the generator's θ and true
/// labels, class means estimated; (b) θ estimated by marginal likelihood (with screening and
/// class multipliers), true labels; (c) the stored predictions (labels as given, 10 % wrong).
/// The floor: the true soil with the contact unknown. Also how well the measured plastic pipes
/// pin their own u: the fit's σ(ln c_S) from its information and its actual error.
fn oracle(networks: u64, segments: usize, seed0: u64, jobs: usize, cells: &str) {
    use pipewave::db::field::field_inputs;
    use pipewave::db::pages::segments_page;
    use pipewave::field::model::{Field, HyperSource, Scales};
    use pipewave::field::predict::predict_speed;
    use pipewave::field::{length_bounds, sites_of};
    use pipewave::synth::field::wave_speeds;
    let root = std::env::temp_dir().join(format!("pipewave-field-oracle-{}", std::process::id()));
    let cells = if cells.is_empty() {
        "15:350,15:1000"
    } else {
        cells
    };
    for (a, &frac) in MEASURED_FRACTIONS.iter().enumerate() {
        for (b, &ell) in CORRELATION_LENGTHS_M.iter().enumerate() {
            if !selected(cells, frac, ell) {
                continue;
            }
            let names = [
                "(a) true θ, true labels, true unit means",
                "(a') true θ, true labels, means estimated",
                "(b) θ estimated, true labels",
                "(b') θ estimated, labels as today",
                "(c) today's field (stored predictions)",
                "floor: true soil, contact unknown",
                "(b-T) θ estimated but T true, true labels",
                "(b-Bl) B, ℓ true, T estimated, true labels",
                "(b-S) θ estimated, screening of (a'), true labels",
                "(a-S) true θ, screening of (b), true labels",
                "(b-m) θ estimated, members true labels, targets as today",
                "(b-t) θ estimated, members as today, targets true labels",
            ];
            let mut rungs: Vec<Rung> = names.iter().map(|_| Rung::default()).collect();
            // Measured plastic pipes: (σ of ln c_S from the information, error of ln c_S).
            let mut pinned: Vec<(f64, f64)> = Vec::new();
            let mut hypers = Vec::new();
            // χ² = dᵀ I d of each measured fit's error d = û − u_true: [plastic, metal].
            let mut fit_chi2: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
            for n in 0..networks {
                let seed = seed0 + 100 * (3 * a + b) as u64 + n;
                let opts = options(segments, seed, ell, frac);
                let geo = geology(&opts).expect("units");
                let stiffest = (0..geo.units.len())
                    .max_by(|&i, &j| geo.units[i].mean[1].total_cmp(&geo.units[j].mean[1]))
                    .expect("a unit");
                let net = Network::build(&opts, root.join(format!("n{seed}")), jobs);
                let conn = rusqlite::Connection::open(&net.db).expect("database opens");
                let inputs = field_inputs(&conn).expect("field inputs");
                let (sites, obs, _) = sites_of(&inputs);
                let bounds = length_bounds(&sites);
                let by_id: HashMap<&str, &SynthSegment> =
                    net.segments.iter().map(|s| (s.id.as_str(), s)).collect();
                let true_u = |s: &SynthSegment| {
                    let (p, q) = wave_speeds(s.soil_modulus, s.soil_poisson, s.soil_density);
                    [p.ln(), q.ln()]
                };
                let mut obs_true = obs.clone();
                for site in &sites {
                    let Some(m) = site.member else { continue };
                    let s = by_id[site.segment_id.as_str()];
                    obs_true[m].class = s.unit.expect("unit");
                    {
                        let tu = true_u(s);
                        let d = [obs[m].u[0] - tu[0], obs[m].u[1] - tu[1]];
                        let chi2 = obs[m].info.quad(d);
                        fit_chi2[usize::from(!s.material.is_plastic())].push(chi2);
                    }
                    if s.material.is_plastic() {
                        let sd = obs[m].noise().ss.sqrt();
                        pinned.push((sd, obs[m].u[1] - true_u(s)[1]));
                    }
                }
                let nk = geo.units.len();
                // The generator's θ, with the same screening of the fits the field cannot
                // explain as the fitted field does (two rounds), so that only θ differs.
                let screened_with = |means: bool| {
                    let mut scales = Scales::unit(nk, obs_true.len());
                    let mut f = None;
                    for _ in 0..=pipewave::field::model::SCREEN_ROUNDS {
                        let mut field = Field::with_scales(
                            obs_true.clone(),
                            nk,
                            bounds,
                            true_hyper(ell),
                            HyperSource::MarginalLikelihood,
                            scales.clone(),
                        );
                        if means {
                            for (k, u) in geo.units.iter().enumerate() {
                                field.class_mean[2 * k] = u.mean[0];
                                field.class_mean[2 * k + 1] = u.mean[1];
                            }
                            field.class_cov.fill(0.0);
                        }
                        scales.information = field.screen().iter().map(|x| x.scale).collect();
                        f = Some(field);
                    }
                    f.expect("a field")
                };
                let oracle = screened_with(true);
                let oracle_means = screened_with(false);
                let estimated = Field::fit(obs_true.clone(), nk, bounds);
                let t_true = Field::with_scales(
                    obs_true.clone(),
                    nk,
                    bounds,
                    Hyper {
                        t: true_hyper(ell).t,
                        ..estimated.hyper
                    },
                    HyperSource::MarginalLikelihood,
                    estimated.scales.clone(),
                );
                let b_s = Field::with_scales(
                    obs_true.clone(),
                    nk,
                    bounds,
                    estimated.hyper,
                    HyperSource::MarginalLikelihood,
                    Scales {
                        class: estimated.scales.class.clone(),
                        information: oracle_means.scales.information.clone(),
                        means: Vec::new(),
                    },
                );
                let a_s = Field::with_scales(
                    obs_true.clone(),
                    nk,
                    bounds,
                    true_hyper(ell),
                    HyperSource::MarginalLikelihood,
                    Scales {
                        class: vec![[1.0, 1.0]; nk],
                        information: estimated.scales.information.clone(),
                        means: Vec::new(),
                    },
                );
                let n_screened =
                    |f: &Field| f.scales.information.iter().filter(|&&x| x < 1.0).count();
                println!(
                    "  network {seed}: screened with true θ {}, with estimated θ {} of {}; class multipliers {:?}",
                    n_screened(&oracle_means),
                    n_screened(&estimated),
                    obs_true.len(),
                    estimated.scales.class
                );
                let bl_true = Field::with_scales(
                    obs_true,
                    nk,
                    bounds,
                    Hyper {
                        t: estimated.hyper.t,
                        ..true_hyper(ell)
                    },
                    HyperSource::MarginalLikelihood,
                    estimated.scales.clone(),
                );
                let today_names = sites_of(&inputs).2;
                let today = Field::fit(obs, today_names.len(), bounds);
                let unit_of_name: HashMap<&str, usize> = geo
                    .units
                    .iter()
                    .enumerate()
                    .map(|(k, u)| (u.class.0, k))
                    .collect();
                let name_of_unit: HashMap<usize, usize> = today_names
                    .iter()
                    .enumerate()
                    .filter_map(|(i, n)| unit_of_name.get(n.as_str()).map(|&u| (u, i)))
                    .collect();
                hypers.push(estimated.hyper);
                let (pred, _) = speeds(&net.db);
                let site_of: HashMap<&str, usize> = sites
                    .iter()
                    .enumerate()
                    .map(|(i, s)| (s.segment_id.as_str(), i))
                    .collect();
                let mut after: Option<String> = None;
                loop {
                    let page = segments_page(&conn, after.as_deref(), 256).expect("page");
                    let Some(last) = page.last() else { break };
                    after = Some(last.segment_id.clone());
                    for rec in &page {
                        let s = by_id[rec.segment_id.as_str()];
                        let site = &sites[site_of[rec.segment_id.as_str()]];
                        if s.measured || !s.material.is_plastic() {
                            continue;
                        }
                        let Some(truth) = s.leak_band_speed else {
                            continue;
                        };
                        let Ok(data) = pipewave::rows::segment_data(rec) else {
                            continue;
                        };
                        let unit = s.unit.expect("unit");
                        let stiff = unit == stiffest;
                        let tu = true_u(s);
                        // Each rung's field states its errors as it would (P92: widened where its
                        // θ was estimated).
                        let mut score =
                            |r: usize, mean: [f64; 2], cov: Sym2, widening: [f64; 2]| {
                                if cov.ss > 0.0 {
                                    rungs[r].zu.push((tu[1] - mean[1]) / cov.ss.sqrt());
                                }
                                let p = predict_speed(
                                    &data,
                                    opts.model,
                                    opts.contact_mode,
                                    mean,
                                    cov,
                                    widening,
                                );
                                if let Some(b) = p.band {
                                    let e = b.value / truth - 1.0;
                                    rungs[r].push(e, stiff, (b.value - truth).abs() <= 2.0 * b.std);
                                }
                            };
                        let post = oracle.posterior(site.pos, unit, None);
                        score(0, post.mean, post.cov, [1.0; 2]);
                        let post = oracle_means.posterior(site.pos, unit, None);
                        score(1, post.mean, post.cov, [1.0; 2]);
                        let post = estimated.posterior(site.pos, unit, None);
                        score(2, post.mean, post.cov, estimated.widening);
                        let post = if site.classes.is_empty() {
                            today.posterior(site.pos, site.class.unwrap_or(0), None)
                        } else {
                            today.mixture_posterior(site.pos, &site.classes, None)
                        };
                        score(3, post.mean, post.cov, today.widening);
                        // Members labelled by their true unit, the target's class as today
                        // (today's class indices mapped to units by name).
                        let mapped: Vec<(usize, f64)> = if site.classes.is_empty() {
                            vec![(site.class.unwrap_or(0), 1.0)]
                        } else {
                            site.classes.clone()
                        }
                        .into_iter()
                        .filter_map(|(k, p)| {
                            unit_of_name.get(today_names[k].as_str()).map(|&u| (u, p))
                        })
                        .collect();
                        if !mapped.is_empty() {
                            let post = estimated.mixture_posterior(site.pos, &mapped, None);
                            score(10, post.mean, post.cov, estimated.widening);
                        }
                        if let Some(&k) = name_of_unit.get(&unit) {
                            let post = today.posterior(site.pos, k, None);
                            score(11, post.mean, post.cov, today.widening);
                        }
                        score(5, true_u(s), Sym2::default(), [1.0; 2]);
                        let post = t_true.posterior(site.pos, unit, None);
                        score(6, post.mean, post.cov, t_true.widening);
                        let post = bl_true.posterior(site.pos, unit, None);
                        score(7, post.mean, post.cov, bl_true.widening);
                        let post = b_s.posterior(site.pos, unit, None);
                        score(8, post.mean, post.cov, b_s.widening);
                        let post = a_s.posterior(site.pos, unit, None);
                        score(9, post.mean, post.cov, a_s.widening);
                        if let Some(&(Some(c), Some(sd))) = pred.get(&s.id) {
                            rungs[4].push(c / truth - 1.0, stiff, (c - truth).abs() <= 2.0 * sd);
                        }
                    }
                    if page.len() < 256 {
                        break;
                    }
                }
                let _ = std::fs::remove_dir_all(&net.dir);
            }
            println!(
                "oracle ladder, measured {:.0} % ℓ {ell} m ({networks} networks):",
                100.0 * frac
            );
            for (r, name) in rungs.iter().zip(names) {
                r.report(name);
            }
            let mut sd: Vec<f64> = pinned.iter().map(|p| p.0).collect();
            let mut err: Vec<f64> = pinned.iter().map(|p| p.1.abs()).collect();
            sd.sort_by(f64::total_cmp);
            err.sort_by(f64::total_cmp);
            let rms = (pinned.iter().map(|p| (p.1 / p.0).powi(2)).sum::<f64>()
                / pinned.len().max(1) as f64)
                .sqrt();
            println!(
                "  measured plastic pipes (n {}): fit σ(ln c_S) median {:.3} p90 {:.3}; |fit − true| \
                 ln c_S median {:.3} p90 {:.3}; rms error/σ {:.2} (generator: field σ {:.2}, pipe \
                 scatter {:.2})",
                pinned.len(),
                quantile(&sd, 0.5),
                quantile(&sd, 0.9),
                quantile(&err, 0.5),
                quantile(&err, 0.9),
                rms,
                pipewave::synth::field::UNIT_SPREAD_LN_CS,
                pipewave::synth::field::PIPE_SCATTER_LN
            );
            for (k, name) in ["plastic", "metal"].iter().enumerate() {
                let mut c = fit_chi2[k].clone();
                c.sort_by(f64::total_cmp);
                let over = |t: f64| {
                    100.0 * c.iter().filter(|&&x| x > t).count() as f64 / c.len().max(1) as f64
                };
                println!(
                    "  measured {name} fits: χ² of (û − u_true) in their information: median {:.2}                      p90 {:.1} (χ²₂: 1.39, 4.6); beyond 13.8: {:.1} % (χ²₂: 0.1 %), beyond 4.6: {:.1} %",
                    quantile(&c, 0.5),
                    quantile(&c, 0.9),
                    over(13.8),
                    over(4.6)
                );
            }
            for h in &hypers {
                println!(
                    "  estimated θ: ℓ {:.0} m, B ({:.4}, {:.4}, {:.4}), T ({:.5}, {:.5})",
                    h.ell, h.b.pp, h.b.ps, h.b.ss, h.t.pp, h.t.ss
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&root);
}

fn arg<T: std::str::FromStr>(args: &[String], i: usize, default: T) -> T {
    args.get(i).and_then(|a| a.parse().ok()).unwrap_or(default)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("baseline") | None => baseline(
            arg(&args, 1, 20),
            arg(&args, 2, 600),
            arg(&args, 3, 380_001),
        ),
        Some("grid") => grid(
            arg(&args, 1, 5),
            arg(&args, 2, 600),
            arg(&args, 3, 390_001),
            arg(&args, 4, 2),
            args.get(5).map_or("", String::as_str),
        ),
        Some("plan") => plan_check(
            arg(&args, 1, 3),
            arg(&args, 2, 600),
            arg(&args, 3, 395_001),
            arg(&args, 4, 2),
        ),
        Some("oracle") => oracle(
            arg(&args, 1, 5),
            arg(&args, 2, 600),
            arg(&args, 3, 392_001),
            arg(&args, 4, 2),
            args.get(5).map_or("", String::as_str),
        ),
        Some("zones") => zones_check(
            arg(&args, 1, 10),
            arg(&args, 2, 600),
            arg(&args, 3, 640_001),
            arg(&args, 4, 1),
            arg(&args, 5, 0.15),
            arg(&args, 6, 16),
        ),
        Some(other) => {
            eprintln!("unknown mode '{other}' (baseline, grid, plan, oracle or zones)");
            std::process::exit(2);
        }
    }
}
