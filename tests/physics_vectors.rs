//! The forward model against the reference vectors of `tests/data/vectors/` (copied from the
//! project's shared reference set; see its README for how they were produced: an independent
//! Python implementation checked against mpmath at 30–320 digits) and against spec Appendix A.

// Reference values are copied verbatim from the spec, digits and all.
#![allow(clippy::excessive_precision)]

mod common;

use common::*;
use num_complex::Complex64;
use pipewave::physics::solver::{solve_curve, Continuation};
use pipewave::physics::{ContactMode, Evaluator, Model, SoilWaves};
use pipewave::special::{bessel_j_ratio, hankel_ratio, sqrt_plus};

/// T13: H0/H1 and J0/J1 at the 393 points of hankel_ratio.csv, to 1e-12 relative (the
/// README's suggested tolerance; scipy's Amos differs by up to 2.9e-14 from these values).
#[test]
fn hankel_and_bessel_ratios_match_vectors() {
    let rows = read_csv("vectors/hankel_ratio.csv");
    assert_eq!(rows.len(), 393);
    let (mut worst_h, mut worst_j) = (0.0f64, 0.0f64);
    for r in &rows {
        let z = r.c("z_re", "z_im");
        let h_ref = r.c("h0_over_h1_re", "h0_over_h1_im");
        let j_ref = r.c("j0_over_j1_re", "j0_over_j1_im");
        let h = -hankel_ratio(z).unwrap_or_else(|e| panic!("H ratio at {z}: {e}"));
        let j = bessel_j_ratio(z).unwrap_or_else(|e| panic!("J ratio at {z}: {e}"));
        let (eh, ej) = (rel(h, h_ref), rel(j, j_ref));
        assert!(
            eh <= 1e-12,
            "H0/H1({z}) = {h}, reference {h_ref}, rel {eh:e}"
        );
        assert!(
            ej <= 1e-12,
            "J0/J1({z}) = {j}, reference {j_ref}, rel {ej:e}"
        );
        worst_h = worst_h.max(eh);
        worst_j = worst_j.max(ej);
    }
    eprintln!("hankel_ratio.csv: worst relative error H {worst_h:e}, J {worst_j:e}");
}

/// Soil stiffness K11, K12, K21, K22, K_slip and the branch of k_dr, k_sr at the 62 cases of
/// soil_stiffness.csv, to 1e-10 relative per complex entry (issue 2).
#[test]
fn soil_stiffness_matches_vectors() {
    let rows = read_csv("vectors/soil_stiffness.csv");
    assert_eq!(rows.len(), 62);
    let mut worst = 0.0f64;
    for r in &rows {
        let id = r.s("case_id");
        let omega = r.f("omega_rad_s");
        let k1 = r.c("k_re_rad_per_m", "k_im_np_per_m");
        let a = r.f("mean_radius_m");
        let sw = SoilWaves::new(
            r.f("soil_youngs_modulus_pa"),
            r.f("soil_poisson"),
            r.f("soil_density_kg_m3"),
            r.f("soil_loss_factor"),
            omega,
        );
        let qp = sqrt_plus(sw.kp2 - k1 * k1);
        let qs = sqrt_plus(sw.ks2 - k1 * k1);
        assert!(
            rel(qp, r.c("kdr_re_rad_per_m", "kdr_im_rad_per_m")) < 1e-12,
            "{id} k_dr"
        );
        assert!(
            rel(qs, r.c("ksr_re_rad_per_m", "ksr_im_rad_per_m")) < 1e-12,
            "{id} k_sr"
        );
        let k = sw.stiffness(k1, a).unwrap();
        for (name, got, want) in [
            ("K11", k.k11, r.c("k11_re_pa_per_m", "k11_im_pa_per_m")),
            ("K12", k.k12, r.c("k12_re_pa_per_m", "k12_im_pa_per_m")),
            ("K21", k.k21, r.c("k21_re_pa_per_m", "k21_im_pa_per_m")),
            ("K22", k.k22, r.c("k22_re_pa_per_m", "k22_im_pa_per_m")),
            (
                "Kslip",
                k.slip(),
                r.c("kslip_re_pa_per_m", "kslip_im_pa_per_m"),
            ),
        ] {
            let e = rel(got, want);
            assert!(
                e <= 1e-10,
                "{id} {name} = {got}, reference {want}, rel {e:e}"
            );
            worst = worst.max(e);
        }
    }
    eprintln!("soil_stiffness.csv: worst relative error {worst:e}");
}

/// T12: every row of dispersion_roots.csv. Non-grazing rows to 1e-10 relative on k1 (the spec's
/// tolerance; the issue asks 1e-8 in |k1|). The 3 near-grazing rows are solved and reported;
/// they are asserted only to 1e-6, because the root there depends on which side of the branch
/// cut it lies and two conforming implementations may disagree (model §5.6 item 5).
#[test]
fn dispersion_roots_match_vectors() {
    let rows = read_csv("vectors/dispersion_roots.csv");
    assert_eq!(rows.len(), 392);
    let mut worst = 0.0f64;
    let mut grazing = Vec::new();
    for r in &rows {
        let id = r.s("case_id");
        let sys = system_from_row(r);
        let omega = r.f("omega_rad_s");
        let want = r.c("k_re_rad_per_m", "k_im_np_per_m");
        let got = solve_curve(&sys, &[omega], Continuation::default())
            .pop()
            .unwrap()
            .unwrap_or_else(|e| panic!("{id}: {e}"));
        let e = rel(got.k1, want);
        if r.s("near_grazing") == "1" {
            grazing.push((id.to_string(), e));
            assert!(
                e <= 1e-6,
                "{id} (near grazing): {} vs {want}, rel {e:e}",
                got.k1
            );
            assert!(
                got.flags.near_grazing,
                "{id} should be flagged near_grazing"
            );
        } else {
            assert!(
                e <= 1e-10,
                "{id}: k1 = {}, reference {want}, rel {e:e}",
                got.k1
            );
            worst = worst.max(e);
        }
        // Growing waves only where the reference has them (the `printed` defect, R383/R389).
        assert_eq!(
            got.flags.growing_wave,
            want.im > 0.0,
            "{id} growing-wave flag"
        );
    }
    eprintln!("dispersion_roots.csv: worst non-grazing relative error {worst:e}");
    for (id, e) in grazing {
        eprintln!("  near-grazing row {id}: relative difference {e:e}");
    }
}

/// The inversion's fast settings (Newton with the analytic dF/dk1, step tolerance 1e-10, early
/// stop on visibly quadratic convergence) against every non-grazing reference root: with the
/// spec's ramp they must find the same roots to 1e-9; without a ramp (the search's path) the
/// root may differ only where the direct start is ambiguous, which the fit checks on the
/// reference path at its optimum.
#[test]
fn fast_newton_settings_find_the_reference_roots() {
    use pipewave::physics::solver::Tolerance;
    let rows = read_csv("vectors/dispersion_roots.csv");
    let (mut worst, mut direct_agree, mut n) = (0.0f64, 0usize, 0usize);
    for r in rows.iter().filter(|r| r.s("near_grazing") == "0") {
        let sys = system_from_row(r);
        let omega = r.f("omega_rad_s");
        let want = r.c("k_re_rad_per_m", "k_im_np_per_m");
        let ramp = Continuation {
            tolerance: Tolerance::FAST,
            ..Continuation::default()
        };
        let got = solve_curve(&sys, &[omega], ramp).pop().unwrap();
        let got = got.unwrap_or_else(|e| panic!("{}: {e}", r.s("case_id")));
        let e = rel(got.k1, want);
        assert!(
            e <= 1e-9,
            "{}: {} vs {want} ({e:e})",
            r.s("case_id"),
            got.k1
        );
        worst = worst.max(e);
        let direct = Continuation {
            ramp_points: 0,
            tolerance: Tolerance::FAST,
        };
        n += 1;
        if let Ok(d) = solve_curve(&sys, &[omega], direct).pop().unwrap() {
            if rel(d.k1, want) <= 1e-9 {
                direct_agree += 1;
            }
        }
    }
    eprintln!(
        "fast settings: worst {worst:e} with the ramp; without a ramp {direct_agree}/{n} agree"
    );
    assert!(direct_agree as f64 >= 0.97 * n as f64, "{direct_agree}/{n}");
}

/// Spec Appendix A.2: K, α and F at a fixed k1 for cases A and B, every model and reading.
#[test]
fn appendix_a2_stiffness_alpha_and_residual() {
    type Table = [(Model, ContactMode, Complex64, Complex64); 6];
    let a_table: Table = [
        (
            Model::Seed,
            ContactMode::Reciprocal,
            c(-6.104334471422197e-02, 8.332713631565646e-03),
            c(1.811836734353850e-02, -3.502596308096797e-03),
        ),
        (
            Model::Full,
            ContactMode::Reciprocal,
            c(-6.736157495958445e-02, 8.847618020849763e-03),
            c(1.475270612488305e-02, -3.163090459361230e-03),
        ),
        (
            Model::Seed,
            ContactMode::Printed,
            c(-6.090847451772198e-02, 8.098367355142281e-03),
            c(1.817658890946700e-02, -3.610548099388761e-03),
        ),
        (
            Model::Full,
            ContactMode::Printed,
            c(-6.721395721111527e-02, 8.588774030845648e-03),
            c(1.481719290236244e-02, -3.284150096734053e-03),
        ),
        (
            Model::Seed,
            ContactMode::Blend,
            c(-6.099452952199912e-02, 8.250293952435320e-03),
            c(1.813946594438914e-02, -3.540587170980660e-03),
        ),
        (
            Model::Full,
            ContactMode::Blend,
            c(-6.730829812417238e-02, 8.756624141966176e-03),
            c(1.477600689356884e-02, -3.205674536821294e-03),
        ),
    ];
    let b_table: Table = [
        (
            Model::Seed,
            ContactMode::Reciprocal,
            c(-1.252261419270151e-01, 1.789232674200027e-01),
            c(5.557951503915412e+00, -7.714034216464434e-01),
        ),
        (
            Model::Full,
            ContactMode::Reciprocal,
            c(-1.313563479572429e-01, 1.789244727577769e-01),
            c(4.658232673401891e+00, -2.851226965893785e-01),
        ),
        (
            Model::Seed,
            ContactMode::Printed,
            c(-1.226283365445646e-01, 1.660772089929980e-01),
            c(5.494625922910142e+00, -1.010418049212901e+00),
        ),
        (
            Model::Full,
            ContactMode::Printed,
            c(-1.286072941492977e-01, 1.656045624998628e-01),
            c(4.585428128878696e+00, -5.492050509977915e-01),
        ),
        (
            Model::Seed,
            ContactMode::Blend,
            c(-1.237725388501746e-01, 1.736391612444802e-01),
            c(5.537540721561898e+00, -8.727202781361019e-01),
        ),
        (
            Model::Full,
            ContactMode::Blend,
            c(-1.298498079314792e-01, 1.734745184414361e-01),
            c(4.634280181311762e+00, -3.964179740833105e-01),
        ),
    ];
    let cases: [(&str, f64, Complex64, [Complex64; 4], &Table); 2] = [
        (
            "A",
            3121.958,
            c(2.5, -0.01),
            [
                c(-1.262062810592974e+08, -5.988150883480679e+08),
                c(-1.302466109106628e+07, -8.261721196212716e+06),
                c(-1.503736704227263e+08, -9.723738150785354e+08),
                c(-1.507519481370477e+08, -9.722842302685918e+08),
            ],
            &a_table,
        ),
        (
            "B",
            2.0 * std::f64::consts::PI * 400.0,
            c(8.0, -0.9),
            [
                c(-7.591123407231911e+07, -3.263068278943459e+08),
                c(-4.006978475220171e+07, -8.874322580976002e+06),
                c(-9.409768801546982e+07, -5.992444591624284e+08),
                c(-9.719794041808145e+07, -5.952865583384321e+08),
            ],
            &b_table,
        ),
    ];
    for (name, omega, k1, kref, table) in cases {
        for &(model, mode, alpha_ref, f_ref) in table.iter() {
            let sys = if name == "A" {
                case_a(case_a_soil(), 0.3, model, mode)
            } else {
                case_b(case_b_soil(), 0.3, model, mode)
            };
            let ev = Evaluator::new(&sys, omega);
            let k = ev.stiffness(k1).unwrap();
            assert!(rel(k.k11, kref[0]) < 1e-10, "{name} K11");
            assert!(rel(k.k12, kref[1]) < 1e-10, "{name} K12");
            assert_eq!(k.k21, -k.k12, "{name} K21 = -K12 exactly");
            assert!(rel(k.k22, kref[2]) < 1e-10, "{name} K22");
            assert!(rel(k.slip(), kref[3]) < 1e-10, "{name} Kslip");
            let alpha = ev.alpha(k1).unwrap();
            let f = ev.residual(k1).unwrap();
            assert!(
                rel(alpha, alpha_ref) < 1e-10,
                "{name} {model} {mode}: alpha {alpha} vs {alpha_ref}"
            );
            assert!(
                rel(f, f_ref) < 1e-10,
                "{name} {model} {mode}: F {f} vs {f_ref}"
            );
        }
    }
}

fn roots(sys: &pipewave::physics::System, omegas: &[f64]) -> Vec<Complex64> {
    solve_curve(sys, omegas, Continuation::default())
        .into_iter()
        .map(|r| r.unwrap().k1)
        .collect()
}

/// Spec Appendix A.3: roots for cases A and B under every variant listed.
#[test]
fn appendix_a3_roots() {
    let a: [(Model, ContactMode, f64, [Complex64; 4]); 7] = [
        (
            Model::Seed,
            ContactMode::Reciprocal,
            0.0,
            [
                c(2.484482442529013e+00, -6.105502968394585e-03),
                c(3.317412216976127e+00, -9.540380259909820e-03),
                c(5.758513525440872e+00, -2.377644911286502e-02),
                c(8.245247396277474e+00, -4.515335378387982e-02),
            ],
        ),
        (
            Model::Full,
            ContactMode::Reciprocal,
            0.0,
            [
                c(2.487492645359002e+00, -6.190848225577398e-03),
                c(3.321874984222558e+00, -9.686701520866734e-03),
                c(5.769861337540100e+00, -2.431106965051148e-02),
                c(8.269948868050601e+00, -4.671160157847005e-02),
            ],
        ),
        (
            Model::Full,
            ContactMode::Reciprocal,
            1.0,
            [
                c(2.486153976446897e+00, -9.713068105156297e-03),
                c(3.320802815150437e+00, -1.332841740012145e-02),
                c(5.769119339635918e+00, -2.812907922436569e-02),
                c(8.269306200318397e+00, -5.068860689782020e-02),
            ],
        ),
        (
            Model::Full,
            ContactMode::Printed,
            0.5,
            [
                c(2.486878716832447e+00, -7.926776597851223e-03),
                c(3.321380241194647e+00, -1.143418192501773e-02),
                c(5.769515631119502e+00, -2.609274020609656e-02),
                c(8.269650360884023e+00, -4.855071311037333e-02),
            ],
        ),
        (
            Model::Full,
            ContactMode::Blend,
            0.5,
            [
                c(2.486917965518164e+00, -8.006183494251249e-03),
                c(3.321415208072584e+00, -1.152514864576928e-02),
                c(5.769538155083683e+00, -2.620135457299986e-02),
                c(8.269663636379162e+00, -4.866967667354600e-02),
            ],
        ),
        (
            Model::Seed,
            ContactMode::Printed,
            1.0,
            [
                c(2.483390539115046e+00, -8.900026580713066e-03),
                c(3.316536026654660e+00, -1.240505883289081e-02),
                c(5.757910331504767e+00, -2.673856606138223e-02),
                c(8.244733111548939e+00, -4.820383897026519e-02),
            ],
        ),
        (
            Model::Seed,
            ContactMode::Blend,
            0.0,
            [
                c(2.484453843684121e+00, -6.058948233683056e-03),
                c(3.317386826329467e+00, -9.486240043566666e-03),
                c(5.758496957588915e+00, -2.371100840603612e-02),
                c(8.245237176549134e+00, -4.508201468826113e-02),
            ],
        ),
    ];
    for (model, mode, xi, want) in a {
        let got = roots(&case_a(case_a_soil(), xi, model, mode), &TABLE2_OMEGA);
        for (g, w) in got.iter().zip(want) {
            assert!(
                rel(*g, w) < 1e-10,
                "case A {model} {mode} xi={xi}: {g} vs {w}"
            );
        }
    }
    // In vacuo (P39) for case A without soil.
    let sys = case_a(
        pipewave::physics::Soil::none(),
        0.0,
        Model::Seed,
        ContactMode::Reciprocal,
    );
    for (omega, want) in [
        (50.0, c(3.977913180861961e-02, -5.923521262559932e-05)),
        (3121.958, c(2.484875420273997e+00, -3.718986214256781e-03)),
    ] {
        let got = pipewave::physics::dispersion::in_vacuo_root(&sys, omega);
        assert!(
            rel(got, want) < 1e-12,
            "in vacuo at {omega}: {got} vs {want}"
        );
    }
    let tau = 2.0 * std::f64::consts::PI;
    let omegas = [tau * 100.0, tau * 400.0, tau * 800.0];
    let b: [(Model, ContactMode, f64, [Complex64; 3]); 6] = [
        (
            Model::Full,
            ContactMode::Reciprocal,
            1.0,
            [
                c(1.628399898820771e+00, -9.361097538688064e-02),
                c(7.012520087373519e+00, -1.071514120915994e+00),
                c(1.418767801426236e+01, -4.357414546287049e+00),
            ],
        ),
        (
            Model::Full,
            ContactMode::Reciprocal,
            0.0,
            [
                c(1.733843934803210e+00, -6.703811063209489e-02),
                c(7.131729902257522e+00, -8.996770360438963e-01),
                c(1.430149025848397e+01, -4.169484924851283e+00),
            ],
        ),
        (
            Model::Full,
            ContactMode::Blend,
            0.0,
            [
                c(1.724261694528650e+00, -6.079856389311731e-02),
                c(7.129677168828803e+00, -8.675041537999256e-01),
                c(1.433223436070125e+01, -4.151556397128093e+00),
            ],
        ),
        (
            Model::Full,
            ContactMode::Printed,
            1.0,
            [
                c(1.627032646917950e+00, -8.538796484018189e-02),
                c(7.029802420415495e+00, -1.019063992621882e+00),
                c(1.424489600059788e+01, -4.327116656233895e+00),
            ],
        ),
        (
            Model::Seed,
            ContactMode::Printed,
            1.0,
            [
                c(1.625111295362865e+00, -8.393359751551444e-02),
                c(6.876535370798686e+00, -9.443605632944417e-01),
                c(1.340190234793668e+01, -3.450802182716946e+00),
            ],
        ),
        (
            Model::Seed,
            ContactMode::Blend,
            0.5,
            [
                c(1.654409678085734e+00, -9.666150050389534e-02),
                c(6.926727788336511e+00, -9.096933606487012e-01),
                c(1.342853106667839e+01, -3.394136713005861e+00),
            ],
        ),
    ];
    for (model, mode, xi, want) in b {
        let got = roots(&case_b(case_b_soil(), xi, model, mode), &omegas);
        for (g, w) in got.iter().zip(want) {
            assert!(
                rel(*g, w) < 1e-10,
                "case B {model} {mode} xi={xi}: {g} vs {w}"
            );
        }
    }
}

/// Spec Appendix A.4: case C at 500 Hz, baseline and each effect of §8.
#[test]
fn appendix_a4_case_c_and_effects() {
    use pipewave::physics::effects::{thinned, AirContent};
    use pipewave::physics::{Fluid, Soil, System};
    let omega = 2.0 * std::f64::consts::PI * 500.0;
    let base = case_c(case_c_soil(), 0.0, Model::Full, ContactMode::Reciprocal);
    let air = System {
        fluid: AirContent::new(1e-3, 4e5, 1.0, 288.15)
            .unwrap()
            .mix(&Fluid::water()),
        ..base
    };
    let thin = System {
        pipe: thinned(&base.pipe, 0.75).unwrap(),
        ..base
    };
    let damp = System {
        soil: Soil::new(5.0e7, 0.35, 1900.0, 0.05).unwrap(),
        ..base
    };
    let cases: [(&str, System, Complex64, f64, f64); 8] = [
        (
            "baseline",
            base,
            c(2.447016478122723e+00, -5.597262544572225e-03),
            1283.8461,
            0.048617,
        ),
        (
            "seed",
            System {
                model: Model::Seed,
                ..base
            },
            c(2.444688592362709e+00, -5.528309720843252e-03),
            1285.0686,
            0.048018,
        ),
        (
            "eta_m 0.05",
            damp,
            c(2.447060598743940e+00, -5.615875887826560e-03),
            1283.8230,
            0.048779,
        ),
        (
            "air 1e-3",
            air,
            c(5.533487934696424e+00, -2.448971397699097e-03),
            567.7418,
            0.021271,
        ),
        (
            "r_h 0.75",
            thin,
            c(2.553631140146958e+00, -8.123372015835165e-03),
            1230.2453,
            0.070559,
        ),
        (
            "xi 1 reciprocal",
            System {
                contact: 1.0,
                ..base
            },
            c(2.446149640703028e+00, -8.349267035516450e-03),
            1284.3011,
            0.072521,
        ),
        (
            "xi 0 blend",
            System {
                contact_mode: ContactMode::Blend,
                ..base
            },
            c(2.447004074296616e+00, -5.552054016099589e-03),
            1283.8526,
            0.048225,
        ),
        (
            "xi 1 printed",
            System {
                contact: 1.0,
                contact_mode: ContactMode::Printed,
                ..base
            },
            c(2.446135956736541e+00, -8.260192052140044e-03),
            1284.3083,
            0.071747,
        ),
    ];
    for (name, sys, want, speed, att) in cases {
        let r = solve_curve(&sys, &[omega], Continuation::default())
            .pop()
            .unwrap()
            .unwrap();
        assert!(rel(r.k1, want) < 1e-10, "{name}: {} vs {want}", r.k1);
        assert!(
            (r.phase_speed() - speed).abs() < 1e-4,
            "{name} speed {}",
            r.phase_speed()
        );
        assert!(
            (r.attenuation_db() - att).abs() < 1e-6,
            "{name} att {}",
            r.attenuation_db()
        );
    }
    let ck = pipewave::physics::dispersion::korteweg_speed(&base);
    assert!((ck - 1285.4057019379188).abs() < 1e-9, "c_K {ck}");
}
