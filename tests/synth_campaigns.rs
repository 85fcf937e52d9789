//! `pipewave synth --campaigns 2`: a second campaign a year later at the same frequencies with
//! fresh noise, some pipes changed in between (soil, air, wall thinning, wall loss), the
//! truth of each change and its detectability; and a one-campaign network unchanged.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::cli::{ok, pipewave};
use pipewave::physics::Material;
use pipewave::synth::network::{read_truth, NetworkTables, TruthRow, MEASUREMENTS_CSV, TRUTH_CSV};
use pipewave::synth::{
    generate, Change, SynthOptions, FIRST_CAMPAIGN, NOISE_K_RE, SECOND_CAMPAIGN,
};

/// The rows of measurements.csv: per campaign, (segment, frequency) → the cells of Re k,
/// attenuation, k_re_std and attenuation_std as written (equal cells: equal numbers).
type Rows = BTreeMap<String, BTreeMap<(String, String), [String; 4]>>;

/// The rows of a measurements.csv by campaign, with the `measured_on` of each campaign.
fn read_measurements(path: &Path) -> (Rows, BTreeMap<String, Vec<String>>) {
    let mut rdr = csv::Reader::from_path(path).unwrap();
    let h = rdr.headers().unwrap().clone();
    let at = |n: &str| h.iter().position(|c| c == n);
    let (id, f, w) = (
        at("segment_id").unwrap(),
        at("frequency_hz").unwrap(),
        at("omega_rad_s").unwrap(),
    );
    let nums = [
        at("k_re_rad_per_m").unwrap(),
        at("attenuation_np_per_m").unwrap(),
        at("k_re_std").unwrap(),
        at("attenuation_std").unwrap(),
    ];
    let (c, d) = (at("campaign").unwrap(), at("measured_on"));
    let mut rows = Rows::new();
    let mut dates: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for r in rdr.records() {
        let r = r.unwrap();
        let key = (r[id].to_string(), format!("{}|{}", &r[f], &r[w]));
        let v = nums.map(|i| r[i].to_string());
        assert!(
            rows.entry(r[c].to_string())
                .or_default()
                .insert(key, v)
                .is_none(),
            "a (segment, campaign, frequency) twice"
        );
        if let Some(d) = d {
            dates
                .entry(r[c].to_string())
                .or_default()
                .push(r[d].to_string());
        }
    }
    (rows, dates)
}

fn synth(dir: &Path, extra: &[&str]) -> String {
    let mut args = vec!["synth", "--out", dir.to_str().unwrap(), "--force"];
    args.extend_from_slice(extra);
    String::from_utf8(ok(&args).stdout).unwrap()
}

/// The synthetic (re-measured) truth rows by segment.
fn truth_of(dir: &Path) -> BTreeMap<String, TruthRow> {
    read_truth(&dir.join(TRUTH_CSV))
        .unwrap()
        .into_iter()
        .filter(|t| t.source == "synthetic")
        .map(|t| (t.segment_id.clone(), t))
        .collect()
}

/// (1) The network imports, and the database holds both campaigns with equal row counts on
/// every segment, the later one dated a year after and the latest of each segment.
#[test]
fn two_campaigns_import_with_equal_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    synth(
        &net,
        &["--segments", "30", "--seed", "4", "--campaigns", "2"],
    );
    let (rows, dates) = read_measurements(&net.join(MEASUREMENTS_CSV));
    assert_eq!(
        rows.keys().cloned().collect::<Vec<_>>(),
        vec![
            FIRST_CAMPAIGN,
            SECOND_CAMPAIGN,
            "lu2022_table2", // the published cases, undated as before
            "muggleton2004_50hz_bands",
        ]
    );
    assert!(dates[FIRST_CAMPAIGN]
        .iter()
        .all(|d| d.starts_with("2026-05-")));
    assert!(dates[SECOND_CAMPAIGN]
        .iter()
        .all(|d| d.starts_with("2027-05-")));
    let db = tmp.path().join("n.sqlite");
    let db = db.to_str().unwrap();
    ok(&[
        "import",
        "--db",
        db,
        "--segments",
        net.join("segments.csv").to_str().unwrap(),
        "--measurements",
        net.join(MEASUREMENTS_CSV).to_str().unwrap(),
    ]);
    let conn = rusqlite::Connection::open(db).unwrap();
    let count = |campaign: &str| -> i64 {
        conn.query_row(
            "SELECT COUNT(*) FROM measurements WHERE campaign = ?1",
            [campaign],
            |r| r.get(0),
        )
        .unwrap()
    };
    let (a, b) = (count(FIRST_CAMPAIGN), count(SECOND_CAMPAIGN));
    assert_eq!(a, rows[FIRST_CAMPAIGN].len() as i64);
    assert_eq!(a, b);
    assert!(a > 30 * 3, "{a}");
    let segs: Vec<String> = {
        let mut st = conn
            .prepare("SELECT DISTINCT segment_id FROM measurements WHERE campaign = ?1")
            .unwrap();
        st.query_map([FIRST_CAMPAIGN], |r| r.get(0))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap()
    };
    assert_eq!(segs.len(), 30);
    for s in &segs {
        let c = pipewave::db::inventory::campaigns_of(&conn, s).unwrap();
        assert_eq!(c.len(), 2, "{s}");
        assert_eq!(c[0].rows, c[1].rows, "{s}");
        assert_eq!(
            c[1].name, SECOND_CAMPAIGN,
            "{s}: the later campaign is the latest"
        );
    }
}

/// (2) Unchanged pipes: equal noiseless speeds, z = 0, and measured Re k that differ by the
/// noise only. With d = (k_B − k_A)/σ over the rows (σ the stated one of each, equal since
/// the pipe is the same), d ~ N(0, 2): over n rows the mean has sd sqrt(2/n) and the sample
/// variance an sd of about 2 sqrt(2/n). With n > 1500 rows, |mean| < 0.15 and |var − 2| <
/// 0.35 are beyond 4 sd; a second campaign that reused the first one's noise (d = 0) or
/// doubled it fails them.
#[test]
fn unchanged_pipes_differ_by_noise_only() {
    let net = generate(&SynthOptions {
        segments: 400,
        seed: 21,
        defect_fraction: 0.0,
        campaigns: 2,
        changed_fraction: 0.3,
        ..SynthOptions::default()
    });
    let mut d = Vec::new();
    let mut unchanged = 0;
    for s in &net {
        let c = s.second.as_ref().expect("every segment is measured");
        if c.change != Change::None {
            continue;
        }
        unchanged += 1;
        assert_eq!(c.leak_band_speed_after, s.leak_band_speed, "{}", s.id);
        assert_eq!(c.change_z, 0.0, "{}", s.id);
        assert_eq!(c.change_value, None);
        assert_eq!(c.measurements.len(), s.measurements.len());
        for (a, b) in s.measurements.iter().zip(&c.measurements) {
            assert_eq!(a.frequency_hz, b.frequency_hz, "same frequencies");
            assert!((a.k_re_std / b.k_re_std - 1.0).abs() < 1e-12);
            assert_ne!(a.k_re, b.k_re, "fresh noise");
            d.push((b.k_re - a.k_re) / a.k_re_std);
        }
    }
    assert_eq!(unchanged, 400 - 120);
    let n = d.len() as f64;
    assert!(n > 1500.0, "{n}");
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    assert!(mean.abs() < 0.15, "mean {mean} over {n} rows");
    assert!((var - 2.0).abs() < 0.35, "variance {var} over {n} rows");
}

/// (3) Changed pipes: exactly round(F m) of them; before ≠ after; air lowers the leak-band
/// speed, wall thinning lowers it on metal pipes; every cause occurs and the changes spread
/// from undetectable to obvious.
#[test]
fn changed_pipes_state_their_change() {
    let tmp = tempfile::tempdir().unwrap();
    let net = tmp.path().join("net");
    synth(
        &net,
        &[
            "--segments",
            "240",
            "--seed",
            "8",
            "--campaigns",
            "2",
            "--changed-fraction",
            "0.45",
            "--measured-fraction",
            "0.5",
            "--defects",
            "0",
            "--no-real-cases",
        ],
    );
    let truth = truth_of(&net);
    let materials: BTreeMap<String, Material> = csv::Reader::from_path(net.join("segments.csv"))
        .unwrap()
        .deserialize::<BTreeMap<String, String>>()
        .map(|r| {
            let r = r.unwrap();
            (r["segment_id"].clone(), r["material"].parse().unwrap())
        })
        .collect();
    let measured: Vec<&TruthRow> = truth
        .values()
        .filter(|t| t.measured == Some(true))
        .collect();
    assert_eq!(measured.len(), 120);
    for t in truth.values().filter(|t| t.measured == Some(false)) {
        assert_eq!(
            t.change_effect, None,
            "an unmeasured pipe is not re-measured"
        );
    }
    let changed: Vec<&&TruthRow> = measured
        .iter()
        .filter(|t| t.change_effect.as_deref() != Some("none"))
        .collect();
    assert_eq!(changed.len(), (0.45f64 * 120.0).round() as usize);
    let mut causes = BTreeMap::new();
    let (mut small, mut large) = (0, 0);
    for t in &changed {
        let effect = t.change_effect.as_deref().unwrap();
        *causes.entry(effect.to_string()).or_insert(0) += 1;
        let before = t.leak_band_speed_before_m_per_s.unwrap();
        let after = t.leak_band_speed_after_m_per_s.unwrap();
        assert_eq!(Some(before), t.leak_band_speed_m_per_s);
        assert_ne!(before, after, "{}", t.segment_id);
        let z = t.change_z.unwrap();
        assert!(z > 0.0, "{}", t.segment_id);
        small += usize::from(z < 2.0);
        large += usize::from(z >= 3.0);
        let v = t.change_value.unwrap();
        let m = materials[&t.segment_id];
        match effect {
            "air_in_water" => {
                assert!((1e-5..=1e-3).contains(&v), "{v}");
                assert!(after < before, "{}: air must slow the wave", t.segment_id);
            }
            "wall_thinning" => {
                assert!(
                    !m.is_plastic(),
                    "{}: a {m:?} wall does not thin",
                    t.segment_id
                );
                assert!((0.6..=0.9).contains(&v), "{v}");
                assert!(after < before, "{}: a thinner wall is softer", t.segment_id);
            }
            "soil_change" => {
                let e = t.soil_youngs_modulus_pa.unwrap();
                let decades = (v / e).log10().abs();
                assert!((0.03..=0.3 + 1e-12).contains(&decades), "{decades}");
            }
            "pipe_loss" => {
                let typical = m.typical().loss_factor;
                assert!(v > typical && v <= 0.3, "{v} vs {typical}");
            }
            other => panic!("unknown change {other}"),
        }
    }
    for t in &measured {
        if t.change_effect.as_deref() == Some("none") {
            assert_eq!(t.change_z, Some(0.0));
            assert_eq!(
                t.leak_band_speed_before_m_per_s,
                t.leak_band_speed_after_m_per_s
            );
        }
    }
    assert_eq!(causes.len(), 4, "{causes:?}");
    assert!(
        large * 2 > changed.len(),
        "most are detectable: {large} of {}",
        changed.len()
    );
    assert!(small > 0, "some are small");
}

/// (4) The same seed gives the same files.
#[test]
fn same_seed_same_files() {
    let tmp = tempfile::tempdir().unwrap();
    let args = ["--segments", "25", "--seed", "3", "--campaigns", "2"];
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    synth(&a, &args);
    synth(&b, &args);
    for f in ["segments.csv", MEASUREMENTS_CSV, TRUTH_CSV] {
        let (x, y) = (
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
        );
        assert!(x == y, "{f} differs between two runs of one seed");
    }
    let c = tmp.path().join("c");
    synth(&c, &["--segments", "25", "--seed", "4", "--campaigns", "2"]);
    assert_ne!(
        std::fs::read(a.join(MEASUREMENTS_CSV)).unwrap(),
        std::fs::read(c.join(MEASUREMENTS_CSV)).unwrap()
    );
}

/// (5) The first campaign's numbers are those of `--campaigns 1` (the second has its own noise
/// stream and its own change stream), and a one-campaign network is what it was: campaign
/// `synthetic`, no `measured_on` column, no change columns in truth.csv, and the same files as
/// the library's tables of a network generated without the new options.
#[test]
fn first_campaign_is_the_one_campaign_network() {
    let tmp = tempfile::tempdir().unwrap();
    let (one, two) = (tmp.path().join("one"), tmp.path().join("two"));
    let common = [
        "--segments",
        "40",
        "--seed",
        "11",
        "--measured-fraction",
        "0.7",
    ];
    synth(&one, &common);
    let mut with_two = common.to_vec();
    with_two.extend(["--campaigns", "2", "--changed-fraction", "0.5"]);
    synth(&two, &with_two);
    let (r1, d1) = read_measurements(&one.join(MEASUREMENTS_CSV));
    let (r2, _) = read_measurements(&two.join(MEASUREMENTS_CSV));
    assert!(d1.is_empty(), "no measured_on column with one campaign");
    assert_eq!(r1["synthetic"], r2[FIRST_CAMPAIGN]);
    assert_eq!(r1["synthetic"].len(), r2[SECOND_CAMPAIGN].len());
    for case in ["lu2022_table2", "muggleton2004_50hz_bands"] {
        assert_eq!(r1[case], r2[case], "the published cases");
    }
    assert_eq!(
        std::fs::read(one.join("segments.csv")).unwrap(),
        std::fs::read(two.join("segments.csv")).unwrap()
    );
    // truth.csv: the one-campaign file is the two-campaign file without its five new columns.
    let t1 = std::fs::read_to_string(one.join(TRUTH_CSV)).unwrap();
    let t2 = std::fs::read_to_string(two.join(TRUTH_CSV)).unwrap();
    assert!(!t1.lines().next().unwrap().contains("change_"));
    let strip: Vec<String> = t2
        .lines()
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            cells[..cells.len() - 5].join(",")
        })
        .collect();
    assert_eq!(strip, t1.lines().collect::<Vec<_>>());
    // The library's tables of the default options (campaigns 1) are the CLI's files.
    let net = generate(&SynthOptions {
        segments: 40,
        seed: 11,
        measured_fraction: 0.7,
        ..SynthOptions::default()
    });
    assert!(net.iter().all(|s| s.second.is_none()));
    let mut tables = NetworkTables::from_synth(&net, 27700);
    for case in pipewave::synth::network::published::published_cases().unwrap() {
        tables.push_published(case);
    }
    assert_eq!(
        tables.measurements_csv(),
        std::fs::read_to_string(one.join(MEASUREMENTS_CSV)).unwrap()
    );
    assert_eq!(tables.truth_csv(), t1);
}

/// The stated σ of the second campaign is 1 % of its own noiseless Re k, so a changed pipe's
/// σ differs from the first campaign's by the change; and `--changed-fraction` needs two
/// campaigns and a fraction.
#[test]
fn options_are_bounded_and_need_two_campaigns() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("x");
    for bad in [
        vec!["--campaigns", "3"],
        vec!["--campaigns", "0"],
        vec!["--campaigns", "2", "--changed-fraction", "1.5"],
        vec!["--changed-fraction", "0.2"],
    ] {
        let mut args = vec!["synth", "--out", out.to_str().unwrap()];
        args.extend(bad.iter().copied());
        let o = pipewave().args(&args).output().unwrap();
        assert!(!o.status.success(), "{bad:?} was accepted");
    }
    assert!(!out.join(MEASUREMENTS_CSV).exists());
    let net = generate(&SynthOptions {
        segments: 20,
        seed: 2,
        defect_fraction: 0.0,
        campaigns: 2,
        changed_fraction: 1.0,
        ..SynthOptions::default()
    });
    for s in &net {
        let c = s.second.as_ref().unwrap();
        assert_ne!(c.change, Change::None, "F = 1 changes every pipe");
        for (a, b) in s.measurements.iter().zip(&c.measurements) {
            // Each stated σ is NOISE_K_RE of its own campaign's noiseless Re k, which the
            // measured Re k is within 6 σ of.
            assert!((b.k_re - b.k_re_std / NOISE_K_RE).abs() < 6.0 * b.k_re_std);
            assert!((a.k_re - a.k_re_std / NOISE_K_RE).abs() < 6.0 * a.k_re_std);
        }
    }
}
