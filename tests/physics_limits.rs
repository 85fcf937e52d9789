//! Closed-form limits and invariants of the model, model §6 (T1–T11) and
//! `tests/data/vectors/limits.md`.

// Reference values are copied verbatim from the spec, digits and all.
#![allow(clippy::excessive_precision)]

mod common;

use common::*;
use num_complex::Complex64;
use pipewave::physics::dispersion::{
    full_model_low_frequency_speed, in_vacuo_root, korteweg_speed,
};
use pipewave::physics::solver::{solve_curve, Continuation, Root};
use pipewave::physics::{ContactMode, Evaluator, Fluid, Model, Pipe, Soil, SoilWaves, System};

const TAU: f64 = 2.0 * std::f64::consts::PI;
const MODES: [ContactMode; 3] = [
    ContactMode::Reciprocal,
    ContactMode::Printed,
    ContactMode::Blend,
];

fn solve(sys: &System, omegas: &[f64]) -> Vec<Root> {
    solve_curve(sys, omegas, Continuation::default())
        .into_iter()
        .map(|r| r.unwrap())
        .collect()
}

/// T1: without soil, `seed` (every contact mode, with P22) equals P39 to 1e-12; `full` differs
/// by the axial inertia and ψ: 1.2e-3, 1.3e-3, 2.0e-3, 3.0e-3 for case A.
#[test]
fn t1_in_vacuo() {
    for mode in MODES {
        let sys = case_a(Soil::none(), 0.5, Model::Seed, mode);
        for r in solve(&sys, &TABLE2_OMEGA) {
            let e = rel(r.k1, in_vacuo_root(&sys, r.omega));
            assert!(e <= 1e-12, "seed {mode} in vacuo at {}: {e:e}", r.omega);
        }
    }
    let sys = case_a(Soil::none(), 0.0, Model::Full, ContactMode::Reciprocal);
    let expect = [1.2e-3, 1.3e-3, 2.0e-3, 3.0e-3];
    for (r, want) in solve(&sys, &TABLE2_OMEGA).iter().zip(expect) {
        let e = rel(r.k1, in_vacuo_root(&sys, r.omega));
        assert!(
            e < 1e-2 && (e - want).abs() < 0.06e-3,
            "full in vacuo at {}: {e:e}",
            r.omega
        );
    }
    // limits.md §1 `full` column for case A at 3121.96 rad/s.
    let r = &solve(&sys, &[3121.958])[0];
    assert!(rel(r.k1, c(2.48788796206, -0.00376908165137)) < 1e-10);
}

/// T2: Korteweg. `seed` at 1 Hz matches P45 to 1e-6; `full` matches P46 to 1e-6; case A
/// c_K = 1256.923273357572 m/s; the six materials of limits.md §2.
#[test]
fn t2_korteweg_limit() {
    let rows: [(f64, f64, f64, f64, f64, f64, f64); 6] = [
        (
            1.22e11,
            0.25,
            7800.0,
            0.069,
            0.006,
            1256.923273,
            1255.613927,
        ),
        (1.7e11, 0.28, 7100.0, 0.1, 0.008, 1300.233723, 1299.273609),
        (2.07e11, 0.3, 7850.0, 0.15, 0.008, 1264.300438, 1263.24055),
        (3.3e9, 0.4, 1400.0, 0.05, 0.005, 392.0799766, 390.0787571),
        (2e9, 0.4, 900.0, 0.0845, 0.011, 350.7959519, 349.2651808),
        (2.4e10, 0.2, 2000.0, 0.1, 0.012, 937.0425713, 936.1435742),
    ];
    for (e, nu, rho, a, h, ck_ref, full_ref) in rows {
        let pipe = Pipe::new(e, nu, rho, 0.0, a, h).unwrap();
        let mk = |m| {
            System::new(
                Fluid::water(),
                pipe,
                Soil::none(),
                0.0,
                m,
                ContactMode::Reciprocal,
            )
            .unwrap()
        };
        let (seed, full) = (mk(Model::Seed), mk(Model::Full));
        let ck = korteweg_speed(&seed);
        let cfull = full_model_low_frequency_speed(&full);
        assert!((ck / ck_ref - 1.0).abs() < 1e-9, "c_K {ck} vs {ck_ref}");
        assert!(
            (cfull / full_ref - 1.0).abs() < 1e-9,
            "P46 {cfull} vs {full_ref}"
        );
        let c_seed = solve(&seed, &[TAU])[0].phase_speed();
        let c_full = solve(&full, &[TAU])[0].phase_speed();
        assert!(
            (c_seed / ck - 1.0).abs() <= 1e-6,
            "seed 1 Hz {c_seed} vs c_K {ck}"
        );
        assert!(
            (c_full / cfull - 1.0).abs() <= 1e-6,
            "full 1 Hz {c_full} vs P46 {cfull}"
        );
        assert!(c_full < ck, "full is below c_K");
    }
    let sys = case_a(Soil::none(), 0.0, Model::Seed, ContactMode::Reciprocal);
    assert!((korteweg_speed(&sys) - 1256.923273357572).abs() < 1e-9);
}

/// T3: soil modulus → 0 recovers the in-vacuo root, the difference shrinking like √E_m:
/// 1.83e-5, 1.83e-6, 1.83e-7, 1.83e-8 for E_m = 1e3, 1e1, 1e-1, 1e-3 Pa (case A soil density).
#[test]
fn t3_soil_modulus_to_zero() {
    let mut diffs = Vec::new();
    for em in [1e3, 1e1, 1e-1, 1e-3] {
        let soil = Soil::new_unbounded(em, 0.3326, 1999.0, 0.0).unwrap();
        let sys = case_a(soil, 0.0, Model::Seed, ContactMode::Reciprocal);
        let d = solve(&sys, &TABLE2_OMEGA)
            .iter()
            .map(|r| rel(r.k1, in_vacuo_root(&sys, r.omega)))
            .fold(0.0, f64::max);
        diffs.push(d);
    }
    for (d, want) in diffs.iter().zip([1.83e-5, 1.83e-6, 1.83e-7, 1.83e-8]) {
        assert!(
            (d / want - 1.0).abs() < 0.01,
            "max diff {d:e}, reference {want:e}"
        );
    }
    for w in diffs.windows(2) {
        assert!(w[1] < w[0] && (w[0] / w[1] - 10.0).abs() < 1.0, "{diffs:?}");
    }
    assert!(diffs[2] < 1e-6);
    // limits.md §5: a = 80 mm, h = 6.8 mm at 10314.48 rad/s.
    let pipe = Pipe::new(1.22e11, 0.25, 7800.0, 0.01, 0.08, 0.0068).unwrap();
    for (em, want) in [
        (1e7, c(8.28998565538, -3.205180e-02)),
        (1e3, c(8.29059324516, -1.371121e-02)),
    ] {
        let soil = Soil::new_unbounded(em, 0.3326, 1999.0, 0.0).unwrap();
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            0.0,
            Model::Seed,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let r = &solve(&sys, &[10314.48])[0];
        assert!(rel(r.k1, want) < 1e-6, "E_m {em}: {} vs {want}", r.k1);
    }
}

/// T4: static cavity stiffness K22 → −2μ_m/a; radiation loss has the dissipative sign.
#[test]
fn t4_static_cavity_and_radiation_sign() {
    let soil = Soil::new(4.79e7, 0.3326, 1999.0, 0.0).unwrap();
    let mu = soil.lame().1;
    let a = 0.069;
    let k = SoilWaves::new(soil.youngs_modulus, soil.poisson, soil.density, 0.0, 1.0)
        .stiffness(c(1e-3, 0.0), a)
        .unwrap();
    let r = k.k22 * a / mu;
    assert!((r + 2.0).norm() < 1e-4, "K22 a/mu = {r}");
    assert!((k.slip() * a / mu + 2.0).norm() < 1e-4);
    // limits.md §3: 4.5e7 Pa soil at (1 rad/s, 1e-3): -1.99999544231 - 8.895725e-07i.
    let s2 = Soil::new(4.5e7, 0.35, 1999.0, 0.0).unwrap();
    let k2 = SoilWaves::new(4.5e7, 0.35, 1999.0, 0.0, 1.0)
        .stiffness(c(1e-3, 0.0), a)
        .unwrap();
    assert!(rel(k2.k22 * a / s2.lame().1, c(-1.99999544231, -8.895725e-07)) < 1e-10);
    let k3 = SoilWaves::new(soil.youngs_modulus, soil.poisson, soil.density, 0.0, 8000.0)
        .stiffness(c(3.0, 0.0), a)
        .unwrap();
    assert!(k3.k22.im < 0.0, "Im K22 = {}", k3.k22.im);
}

/// T5: reciprocity against K12 from limits.md §3 (rebuilt there from the potentials).
#[test]
fn t5_reciprocity_values() {
    let cases = [
        (
            45e6,
            0.35,
            1999.0,
            0.0,
            0.069,
            3121.958,
            c(2.508, -0.00544),
            c(-13196606.06, -4827119.022),
        ),
        (
            4.0e7,
            1.0 / 3.0,
            1500.0,
            0.0,
            0.0845,
            TAU * 400.0,
            c(7.0, -0.8),
            c(-34823785.25, -10688589.74),
        ),
    ];
    for (e, nu, rho, eta, a, w, k1, k12) in cases {
        let k = SoilWaves::new(e, nu, rho, eta, w).stiffness(k1, a).unwrap();
        assert!(rel(k.k12, k12) < 1e-8, "K12 {} vs {k12}", k.k12);
        assert!((k.k21 + k.k12).norm() <= 1e-12 * k.k12.norm());
    }
}

/// T6: K_slip (P23) equals the Muggleton–Yan closed form (P49) to 1e-10.
#[test]
fn t6_slip_against_muggleton_yan() {
    let (bm, gm, rho) = (5.3e7, 2.0e7, 2000.0);
    let e = 9.0 * bm * gm / (3.0 * bm + gm);
    let nu = (3.0 * bm - 2.0 * gm) / (2.0 * (3.0 * bm + gm));
    let a = 0.0845;
    for (w, k1) in [(TAU * 100.0, c(1.7, -0.05)), (TAU * 400.0, c(7.0, -0.8))] {
        let sw = SoilWaves::new(e, nu, rho, 0.0, w);
        let k = sw.stiffness(k1, a).unwrap();
        let lam = Complex64::from(bm - 2.0 * gm / 3.0);
        let mu = sw.mu;
        assert!(rel(mu, Complex64::from(gm)) < 1e-14);
        let k12 = k1 * k1;
        let qp = pipewave::special::sqrt_plus(sw.kp2 - k12);
        let qs = pipewave::special::sqrt_plus(sw.ks2 - k12);
        let p = pipewave::special::hankel_ratio(qp * a).unwrap();
        let q = pipewave::special::hankel_ratio(qs * a).unwrap();
        let t = 1.0 - 2.0 * k12 / sw.ks2;
        let p49 = -(lam * (sw.kp2 / qp) * t * p
            + 2.0 * mu * t * (qp * p + 1.0 / a)
            + 4.0 * mu * (k12 / sw.ks2) * (qs * q + 1.0 / a));
        let d = rel(k.slip(), p49);
        assert!(d <= 1e-10, "K_slip vs P49 at {w}: {d:e}");
    }
}

/// T7: the slip low-frequency formula P50 is the ω → 0 limit of `seed` + `blend`, ξ = 0, η_p = 0.
#[test]
fn t7_slip_low_frequency() {
    for (pipe, soil) in [
        (
            Pipe::new(1.22e11, 0.25, 7800.0, 0.0, 0.069, 0.006).unwrap(),
            Soil::new(4.5e7, 0.35, 1999.0, 0.0).unwrap(),
        ),
        (
            Pipe::new(2.0e9, 0.4, 900.0, 0.0, 0.0845, 0.011).unwrap(),
            case_b_soil(),
        ),
    ] {
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            0.0,
            Model::Seed,
            ContactMode::Blend,
        )
        .unwrap();
        let mut prev = f64::INFINITY;
        for f in [10.0, 1.0, 0.1] {
            let w = TAU * f;
            let kf = w * (1000.0f64 / 2.25e9).sqrt();
            let mu = soil.lame().1;
            let (a, h) = (pipe.mean_radius, pipe.wall_thickness);
            let k50 = kf
                * (1.0 + (2.0 * 2.25e9 / a) / (pipe.youngs_modulus * h / (a * a) + 2.0 * mu / a))
                    .sqrt();
            let r = &solve(&sys, &[w])[0];
            let d = (r.k1.re - k50).abs() / k50;
            assert!(
                d < prev,
                "not decreasing towards low frequency: {d:e} at {f} Hz"
            );
            prev = d;
        }
        assert!(prev <= 1e-6, "at 0.1 Hz: {prev:e}");
    }
}

/// T8: continuity in frequency over 400-point sweeps (case A 20–2000 Hz, case B 20–1000 Hz),
/// both models, ξ ∈ {0, 1}.
#[test]
fn t8_continuity_in_frequency() {
    for (name, lo, hi) in [("A", 20.0, 2000.0), ("B", 20.0, 1000.0)] {
        for model in [Model::Seed, Model::Full] {
            for xi in [0.0, 1.0] {
                let sys = if name == "A" {
                    case_a(case_a_soil(), xi, model, ContactMode::Reciprocal)
                } else {
                    case_b(case_b_soil(), xi, model, ContactMode::Reciprocal)
                };
                let omegas: Vec<f64> = (0..400)
                    .map(|i| TAU * (lo + (hi - lo) * i as f64 / 399.0))
                    .collect();
                let k: Vec<Complex64> = solve(&sys, &omegas).iter().map(|r| r.k1).collect();
                for w in k.windows(3) {
                    let r = (w[2] - w[1]).norm() / (w[1] - w[0]).norm();
                    assert!(
                        r > 0.5 && r < 1.5,
                        "{name} {model} xi={xi}: increment ratio {r}"
                    );
                    assert!(w[1].re > w[0].re);
                }
            }
        }
    }
}

/// T9: Re k1 decreases strictly with ξ; |Im k1(1)| > |Im k1(0)| (`reciprocal`, `blend`).
#[test]
fn t9_ordering_in_contact() {
    for mode in [ContactMode::Reciprocal, ContactMode::Blend] {
        for model in [Model::Seed, Model::Full] {
            for name in ["A", "B"] {
                let omegas: Vec<f64> = if name == "A" {
                    TABLE2_OMEGA.to_vec()
                } else {
                    vec![TAU * 100.0, TAU * 400.0, TAU * 800.0]
                };
                let roots: Vec<Vec<Complex64>> = (0..=5)
                    .map(|i| {
                        let xi = i as f64 * 0.2;
                        let sys = if name == "A" {
                            case_a(case_a_soil(), xi, model, mode)
                        } else {
                            case_b(case_b_soil(), xi, model, mode)
                        };
                        solve(&sys, &omegas).iter().map(|r| r.k1).collect()
                    })
                    .collect();
                for j in 0..omegas.len() {
                    for i in 1..roots.len() {
                        assert!(
                            roots[i][j].re < roots[i - 1][j].re,
                            "{name} {model} {mode} Re not decreasing at xi step {i}"
                        );
                    }
                    assert!(roots[5][j].im.abs() > roots[0][j].im.abs());
                }
            }
        }
    }
}

/// T10: signs of the damping.
#[test]
fn t10_damping_signs() {
    let lossless = Pipe::new(1.22e11, 0.25, 7800.0, 0.0, 0.069, 0.006).unwrap();
    for model in [Model::Seed, Model::Full] {
        let sys = System::new(
            Fluid::water(),
            lossless,
            Soil::none(),
            0.0,
            model,
            ContactMode::Reciprocal,
        )
        .unwrap();
        for r in solve(&sys, &TABLE2_OMEGA) {
            assert!(r.k1.im.abs() <= 1e-12 * r.k1.norm(), "lossless: {}", r.k1);
        }
        for mode in [ContactMode::Reciprocal, ContactMode::Blend] {
            let systems = [
                case_a(Soil::none(), 0.0, model, mode),
                System::new(Fluid::water(), lossless, case_a_soil(), 0.0, model, mode).unwrap(),
                case_a(
                    Soil::new(4.79e7, 0.3326, 1999.0, 0.05).unwrap(),
                    0.0,
                    model,
                    mode,
                ),
                case_b(case_b_soil(), 0.0, model, mode),
                case_b(case_b_soil(), 1.0, model, mode),
            ];
            for sys in systems {
                for r in solve(&sys, &TABLE2_OMEGA[..2]) {
                    assert!(r.k1.im < 0.0 && r.k1.re > 0.0, "{model} {mode}: {}", r.k1);
                }
            }
        }
    }
    let a0 = solve(
        &case_a(case_a_soil(), 0.0, Model::Full, ContactMode::Reciprocal),
        &TABLE2_OMEGA,
    );
    let a1 = solve(
        &case_a(
            Soil::new(4.79e7, 0.3326, 1999.0, 0.05).unwrap(),
            0.0,
            Model::Full,
            ContactMode::Reciprocal,
        ),
        &TABLE2_OMEGA,
    );
    for (r0, r1) in a0.iter().zip(&a1) {
        assert!(r1.k1.im.abs() > r0.k1.im.abs());
    }
}

/// T11: the `printed` defect: a growing wave for the thin MDPE pipe in stiff soil at 200 Hz;
/// `reciprocal` decays, within 5 % of the exact-elasticity −0.48459.
#[test]
fn t11_printed_defect() {
    let pipe = Pipe::new(1.6e9, 0.4, 900.0, 0.06, 0.0845, 0.003).unwrap();
    let soil = Soil::new(1.6e8, 1.0 / 3.0, 1500.0, 0.0).unwrap();
    let mk = |mode| System::new(Fluid::water(), pipe, soil, 1.0, Model::Full, mode).unwrap();
    let printed = &solve(&mk(ContactMode::Printed), &[TAU * 200.0])[0];
    assert!(
        printed.k1.im > 0.0 && printed.flags.growing_wave,
        "{}",
        printed.k1
    );
    let recip = &solve(&mk(ContactMode::Reciprocal), &[TAU * 200.0])[0];
    assert!(recip.k1.im < 0.0 && !recip.flags.growing_wave);
    assert!((recip.k1.im / -0.48459 - 1.0).abs() < 0.05, "{}", recip.k1);
    // The residual is O(1): the evaluator at the root is at rounding level.
    let ev = Evaluator::new(&mk(ContactMode::Reciprocal), TAU * 200.0);
    assert!(ev.residual(recip.k1).unwrap().norm() < 1e-10);
}

/// Spec §5.6 item 4: the thin MDPE pipe of T11 under `seed`/`reciprocal` leaves the branch near
/// 596 Hz, where Re(k_P² − k1²) changes sign; under `full` Muller fails there. The sweep must
/// report a failure from there on, never a silent wrong number, and must be fine below it.
#[test]
fn failures_are_reported_as_data() {
    let pipe = Pipe::new(1.6e9, 0.4, 900.0, 0.06, 0.0845, 0.003).unwrap();
    let soil = Soil::new(1.6e8, 1.0 / 3.0, 1500.0, 0.0).unwrap();
    for model in [Model::Seed, Model::Full] {
        let sys = System::new(
            Fluid::water(),
            pipe,
            soil,
            1.0,
            model,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let omegas: Vec<f64> = (0..200)
            .map(|i| TAU * (20.0 + 780.0 * i as f64 / 199.0))
            .collect();
        let res = solve_curve(&sys, &omegas, Continuation::default());
        let first_fail = res.iter().position(|r| r.is_err());
        let i = first_fail.unwrap_or_else(|| panic!("{model}: no failure reported up to 800 Hz"));
        let f = omegas[i] / TAU;
        assert!(
            f > 500.0 && f < 650.0,
            "{model}: first failure at {f} Hz: {:?}",
            res[i]
        );
        assert!(res[..i].iter().all(|r| r.as_ref().unwrap().k1.im < 0.0));
        assert!(
            res[i..].iter().all(|r| r.is_err()),
            "after a failure nothing is trusted"
        );
        eprintln!("{model}: {} at {f:.1} Hz", res[i].as_ref().unwrap_err());
    }
    let sys = case_a(case_a_soil(), 0.0, Model::Full, ContactMode::Reciprocal);
    let res = solve_curve(&sys, &[f64::NAN, -1.0, 3121.958], Continuation::default());
    assert_eq!(res[0].as_ref().unwrap_err().code(), "invalid_frequency");
    assert_eq!(res[1].as_ref().unwrap_err().code(), "invalid_frequency");
    assert!(res[2].is_ok());
}

/// Requested frequencies in any order and repeated give the same roots as sorted ones (§5.4).
#[test]
fn order_and_repeats_do_not_matter() {
    let sys = case_b(case_b_soil(), 1.0, Model::Full, ContactMode::Reciprocal);
    let sorted = solve(&sys, &[TAU * 100.0, TAU * 400.0, TAU * 800.0]);
    let shuffled = solve(&sys, &[TAU * 800.0, TAU * 100.0, TAU * 400.0, TAU * 100.0]);
    assert!(rel(shuffled[0].k1, sorted[2].k1) < 1e-13);
    assert!(rel(shuffled[1].k1, sorted[0].k1) < 1e-13);
    assert!(rel(shuffled[2].k1, sorted[1].k1) < 1e-13);
    assert!(rel(shuffled[3].k1, sorted[0].k1) < 1e-13);
}

/// The analytic dF/dk1 used by Newton's method against central differences of F, and F itself
/// against the reference residual, for every model, contact reading and contact value, with
/// and without soil (cases A, B, and B in vacuo).
#[test]
fn residual_derivative_matches_finite_differences() {
    for (name, omega, k1) in [
        ("A", 3121.958, c(2.49, -0.006)),
        ("B", TAU * 400.0, c(7.1, -0.9)),
        ("B0", TAU * 200.0, c(3.6, -0.1)),
    ] {
        for model in [Model::Seed, Model::Full] {
            for mode in MODES {
                for xi in [0.0, 0.5, 1.0] {
                    let sys = match name {
                        "A" => case_a(case_a_soil(), xi, model, mode),
                        "B" => case_b(case_b_soil(), xi, model, mode),
                        _ => case_b(Soil::none(), xi, model, mode),
                    };
                    let ev = Evaluator::new(&sys, omega);
                    let (f, df) = ev.residual_d(k1).unwrap();
                    let f0 = ev.residual(k1).unwrap();
                    assert!(
                        rel(f, f0) < 1e-13,
                        "{name} {model} {mode} {xi}: F {f} vs {f0}"
                    );
                    let h = 1e-6 * k1.norm();
                    let fd =
                        (ev.residual(k1 + h).unwrap() - ev.residual(k1 - h).unwrap()) / (2.0 * h);
                    let e = rel(df, fd);
                    assert!(
                        e < 1e-6,
                        "{name} {model} {mode} xi={xi}: dF {df} vs {fd} ({e:e})"
                    );
                }
            }
        }
    }
}
