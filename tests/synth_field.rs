//! Synthetic networks with geological units (model §7.12): contiguous units, the measured
//! fraction, wrong labels, the truth speeds against the forward model, determinism, and
//! `pipewave synth` with the new options as a user runs it.

use std::collections::HashSet;
use std::path::Path;
use std::process::Command;

use pipewave::invert::assemble::leak_band_speed_of;
use pipewave::physics::{Fluid, Soil, System};
use pipewave::synth::network::{read_truth, NetworkTables, MEASUREMENTS_CSV, TRUTH_CSV};
use pipewave::synth::{
    generate, geology, pipe_of, SynthOptions, SynthSegment, TABLE_CONTACT, TABLE_SOIL_MODULUS,
    TABLE_SOIL_POISSON,
};

fn opts(segments: usize, seed: u64) -> SynthOptions {
    SynthOptions {
        segments,
        seed,
        defect_fraction: 0.0,
        units: 4,
        correlation_length_m: 350.0,
        measured_fraction: 0.15,
        wrong_label_fraction: 0.1,
        ..SynthOptions::default()
    }
}

fn midpoint(s: &SynthSegment) -> (f64, f64) {
    let (a, b) = (s.geometry[0], s.geometry[s.geometry.len() - 1]);
    (0.5 * (a.0 + b.0), 0.5 * (a.1 + b.1))
}

/// Every unit is one connected patch of streets: its segments are linked through neighbours
/// whose midpoints lie within 200 m (the nearest edges of the 120 m × 90 m grid lie 75–180 m
/// apart), and each
/// segment lies in the unit of its nearest centre.
#[test]
fn units_are_contiguous_patches() {
    for seed in [3, 4] {
        let o = opts(300, seed);
        let net = generate(&o);
        let geo = geology(&o).unwrap();
        let units: HashSet<usize> = net.iter().map(|s| s.unit.unwrap()).collect();
        assert_eq!(units.len(), 4, "every unit holds segments");
        for s in &net {
            assert_eq!(geo.unit_at(midpoint(s)), s.unit.unwrap());
        }
        for u in units {
            let members: Vec<(f64, f64)> = net
                .iter()
                .filter(|s| s.unit == Some(u))
                .map(midpoint)
                .collect();
            let mut reached = vec![false; members.len()];
            let mut stack = vec![0];
            reached[0] = true;
            while let Some(i) = stack.pop() {
                for j in 0..members.len() {
                    let d = (members[i].0 - members[j].0).hypot(members[i].1 - members[j].1);
                    if !reached[j] && d < 200.0 {
                        reached[j] = true;
                        stack.push(j);
                    }
                }
            }
            let n = reached.iter().filter(|&&r| r).count();
            assert_eq!(n, members.len(), "unit {u} of seed {seed} falls apart");
        }
    }
}

/// The units span soft to stiff ground, and the soil inside a unit varies smoothly: pipes
/// near each other have closer shear speeds than pipes far apart in the same unit.
#[test]
fn soil_varies_smoothly_inside_units() {
    let o = SynthOptions {
        units: 3,
        ..opts(400, 8)
    };
    let net = generate(&o);
    let geo = geology(&o).unwrap();
    assert_eq!(geo.units[0].class.0, "soft_clay");
    assert_eq!(geo.units[2].class.0, "gravel");
    let cs = |s: &SynthSegment| {
        (s.soil_modulus / (2.0 * (1.0 + s.soil_poisson)) / s.soil_density)
            .sqrt()
            .ln()
    };
    let (mut near, mut far) = ((0.0, 0), (0.0, 0));
    for (i, a) in net.iter().enumerate() {
        for b in &net[i + 1..] {
            if a.unit != b.unit {
                continue;
            }
            let (pa, pb) = (midpoint(a), midpoint(b));
            let d = (pa.0 - pb.0).hypot(pa.1 - pb.1);
            let sq = (cs(a) - cs(b)).powi(2);
            if d < 200.0 {
                near = (near.0 + sq, near.1 + 1);
            } else if d > 1000.0 {
                far = (far.0 + sq, far.1 + 1);
            }
        }
    }
    let (near, far) = (near.0 / near.1 as f64, far.0 / far.1 as f64);
    assert!(near < 0.5 * far, "near {near:.4}, far {far:.4}");
}

/// Exactly round(F n) segments keep their measurements and exactly round(F n) carry a wrong
/// label, which is another unit's class; truth.csv keeps every segment, measurements.csv only
/// the measured, the campaign every one.
#[test]
fn measured_fraction_and_wrong_labels_are_exact() {
    let o = opts(250, 5);
    let net = generate(&o);
    let geo = geology(&o).unwrap();
    assert_eq!(net.len(), 250);
    assert_eq!(net.iter().filter(|s| s.measured).count(), 38); // round(0.15 · 250)
    let wrong: Vec<&SynthSegment> = net.iter().filter(|s| s.soil_label != s.soil_type).collect();
    assert_eq!(wrong.len(), 25);
    let classes: HashSet<&str> = geo.units.iter().map(|u| u.class.0).collect();
    for s in &net {
        assert!(classes.contains(s.soil_label));
        assert_eq!(s.soil_type, geo.units[s.unit.unwrap()].class.0);
    }
    let tables = NetworkTables::from_synth(&net, 27700);
    assert_eq!(tables.truth.len(), 250);
    let with_meas = tables
        .segments
        .iter()
        .filter(|r| !r.measurements.is_empty())
        .count();
    assert_eq!(with_meas, 38);
    for (r, s) in tables.segments.iter().zip(&net) {
        assert_eq!(r.soil_type.as_deref(), Some(s.soil_label));
    }
    let campaign = NetworkTables::campaign(&net, "later");
    assert!(campaign.segments.iter().all(|r| !r.measurements.is_empty()));
    assert_eq!(
        campaign.measurement_count(),
        net.iter().map(|s| s.measurements.len()).sum::<usize>()
    );
    // Another fraction, another exact count.
    let o2 = SynthOptions {
        measured_fraction: 0.05,
        wrong_label_fraction: 0.3,
        ..o
    };
    let net2 = generate(&o2);
    assert_eq!(net2.iter().filter(|s| s.measured).count(), 13);
    assert_eq!(
        net2.iter().filter(|s| s.soil_label != s.soil_type).count(),
        75
    );
}

/// truth.csv's speeds are the leak-band speeds of the forward model: the true soil and
/// contact for the truth, the table soil for the table speed; and plastic pipes see the soil,
/// metal pipes hardly.
#[test]
fn truth_speeds_follow_the_forward_model() {
    let o = opts(60, 6);
    let net = generate(&o);
    for s in net.iter().step_by(7) {
        let pipe = pipe_of(s.material, &s.size);
        let sys = |e, nu, xi| {
            System::new(
                Fluid::water(),
                pipe,
                Soil::new(e, nu, s.soil_density, 0.0).unwrap(),
                xi,
                o.model,
                o.contact_mode,
            )
            .unwrap()
        };
        let truth = leak_band_speed_of(&sys(s.soil_modulus, s.soil_poisson, s.contact));
        assert_eq!(truth, s.leak_band_speed);
        let table = leak_band_speed_of(&sys(TABLE_SOIL_MODULUS, TABLE_SOIL_POISSON, TABLE_CONTACT));
        assert_eq!(table, s.table_leak_band_speed);
    }
    let rel = |s: &SynthSegment| {
        (s.table_leak_band_speed.unwrap() / s.leak_band_speed.unwrap() - 1.0).abs()
    };
    let big = generate(&opts(300, 7));
    let max_metal = big
        .iter()
        .filter(|s| !s.material.is_plastic())
        .map(rel)
        .fold(0.0, f64::max);
    let max_plastic = big
        .iter()
        .filter(|s| s.material.is_plastic())
        .map(rel)
        .fold(0.0, f64::max);
    assert!(max_metal < 0.01, "metal table error up to {max_metal}");
    assert!(
        max_plastic > 0.05,
        "plastic table error only up to {max_plastic}"
    );
}

/// The same options give the same network; another seed another one; networks without units
/// are unchanged by the new options' streams.
#[test]
fn networks_are_deterministic() {
    let o = opts(80, 9);
    let (a, b) = (
        NetworkTables::from_synth(&generate(&o), 27700),
        NetworkTables::from_synth(&generate(&o), 27700),
    );
    assert_eq!(a, b);
    let c = NetworkTables::from_synth(
        &generate(&SynthOptions {
            seed: 10,
            ..o.clone()
        }),
        27700,
    );
    assert_ne!(a.truth_csv(), c.truth_csv());
    // Without units the soils are the ones every earlier network had: the units only replace
    // the soil, the inventory is the same.
    let plain = generate(&SynthOptions {
        units: 0,
        measured_fraction: 1.0,
        wrong_label_fraction: 0.0,
        ..o.clone()
    });
    let united = generate(&o);
    for (p, u) in plain.iter().zip(&united) {
        assert_eq!(
            (p.material, p.size, p.contact),
            (u.material, u.size, u.contact)
        );
        assert!(p.unit.is_none() && p.measured && p.soil_label == p.soil_type);
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `pipewave synth` writes the kept measurements, the campaign and the truth; bad fractions
/// and option clashes fail with exit 2 and say which option.
#[test]
fn synth_cli_writes_units_measured_and_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let net = dir.path().join("net");
    let campaign = dir.path().join("later.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_pipewave"))
        .args(["synth", "--out", s(&net), "--segments", "40", "--seed", "2"])
        .args(["--defects", "0", "--no-real-cases", "--units", "2"])
        .args(["--correlation-length", "500", "--measured-fraction", "0.25"])
        .args(["--wrong-labels", "0.1", "--campaign-out", s(&campaign)])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("measurements kept for 10 of 40"),
        "{stdout}"
    );
    assert!(stdout.contains("4 wrong soil_type labels"), "{stdout}");
    let truth = read_truth(&net.join(TRUTH_CSV)).unwrap();
    assert_eq!(truth.len(), 40);
    assert_eq!(
        truth.iter().filter(|t| t.measured == Some(true)).count(),
        10
    );
    assert_eq!(
        truth.iter().filter(|t| t.label_wrong == Some(true)).count(),
        4
    );
    assert!(truth.iter().all(|t| t.leak_band_speed_m_per_s.is_some()
        && t.table_leak_band_speed_m_per_s.is_some()
        && t.geological_unit.is_some()));
    let ids = |p: &Path| -> HashSet<String> {
        csv::Reader::from_path(p)
            .unwrap()
            .records()
            .map(|r| r.unwrap()[0].to_string())
            .collect()
    };
    assert_eq!(ids(&net.join(MEASUREMENTS_CSV)).len(), 10);
    assert_eq!(ids(&campaign).len(), 40);
    for bad in [
        vec!["--measured-fraction", "1.5"],
        vec!["--wrong-labels", "1.2"],
        vec!["--correlation-length", "300"],
        vec!["--units", "2", "--zones", "2"],
        vec!["--units", "2", "--correlation-length", "0"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_pipewave"))
            .args([
                "synth",
                "--out",
                s(&dir.path().join("bad")),
                "--segments",
                "10",
            ])
            .args(&bad)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{bad:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(bad[0]) || err.contains(bad[2]),
            "{bad:?}: {err}"
        );
    }
}
