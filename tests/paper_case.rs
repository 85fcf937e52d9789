//! The paper's cast-iron field case (Lu et al. 2022, Table 2), under the stated geometry
//! assumption (an inferred DN125: a = 69 mm, h = 6 mm; model §7.7), and the buried MDPE pipe of
//! Muggleton et al. (2004). Data from `tests/data/published/` (see its README for sources).

use pipewave::invert::problem::Problem;
use pipewave::invert::*;
use pipewave::physics::{ContactMode, Model};
use pipewave::types::FitStatus;

/// The case as the sample network carries it (the embedded `tests/data/published` files).
fn paper_data() -> SegmentData {
    pipewave::synth::network::published::lu2022()
        .unwrap()
        .segment_data()
        .unwrap()
}

/// The case as the default method sees it (full model, reciprocal contact, no effects).
fn default_problem(data: &SegmentData) -> Problem<'_> {
    Problem::new(
        data,
        Method::Default,
        Model::Full,
        ContactMode::Reciprocal,
        &[],
    )
}

/// The paper's objective f (P52–P53) at (E_m, ν_m, ξ).
fn paper_f(data: &SegmentData, model: Model, mode: ContactMode, x: [f64; 3]) -> f64 {
    let p = Problem::new(data, Method::Paper, model, mode, &[]);
    p.paper_objective(&p.predict(&x).unwrap())
}

/// Spec §7.8 table 1, column "f at the estimate" and "f at the soil test", all four variants.
#[test]
fn paper_objective_at_published_points_matches_spec() {
    let d = paper_data();
    for (model, mode, f_est, f_test) in [
        (Model::Seed, ContactMode::Reciprocal, 0.7235, 0.7224),
        (Model::Full, ContactMode::Reciprocal, 0.7068, 0.7055),
        (Model::Seed, ContactMode::Printed, 0.6958, 0.6944),
        (Model::Full, ContactMode::Printed, 0.6759, 0.6744),
    ] {
        let a = paper_f(&d, model, mode, [4.79e7, 0.3326, 0.0]);
        let b = paper_f(&d, model, mode, [4.5e7, 0.35, 0.0]);
        assert!(
            (a - f_est).abs() < 5e-4,
            "{model} {mode}: f(estimate) = {a}"
        );
        assert!(
            (b - f_test).abs() < 5e-4,
            "{model} {mode}: f(soil test) = {b}"
        );
    }
}

/// Spec §7.7: deviations (%) of `full`/`reciprocal` at the paper's estimate.
#[test]
fn deviations_at_the_estimate_match_spec() {
    let d = paper_data();
    let p = Problem::new(&d, Method::Paper, Model::Full, ContactMode::Reciprocal, &[]);
    let k = p.predict(&[4.79e7, 0.3326, 0.0]).unwrap();
    let re = [0.82, 0.17, 3.78, 1.35];
    let im = [13.8, 9.8, 11.3, 21.6];
    for (i, (m, k)) in d.measurements.iter().zip(&k).enumerate() {
        let dre = 100.0 * (k.re - m.k_re).abs() / m.k_re;
        let dim = 100.0 * (-k.im - m.attenuation).abs() / m.attenuation;
        assert!((dre - re[i]).abs() < 0.01, "Re deviation {dre} at row {i}");
        assert!((dim - im[i]).abs() < 0.1, "Im deviation {dim} at row {i}");
    }
}

/// The paper's estimate is not the global optimum of this model, nor a stationary point:
/// both the paper's DE and the default method find far lower f, and a local polish started at
/// the estimate moves away from it down the E_m–ν_m valley (model §7.8 items 1–2).
#[test]
fn paper_estimate_is_not_the_optimum() {
    let d = paper_data();
    let f_est = paper_f(
        &d,
        Model::Full,
        ContactMode::Reciprocal,
        [4.79e7, 0.3326, 0.0],
    );
    let paper = fit_segment(
        &d,
        &FitSettings::paper(Model::Full, ContactMode::Reciprocal),
        3,
    );
    assert_ne!(paper.status, FitStatus::Failed);
    assert!(
        paper.misfit < 0.5 * f_est,
        "paper DE f = {} vs estimate {f_est}",
        paper.misfit
    );
    let default = fit_segment(&d, &FitSettings::default(), 3);
    let x = [
        default.soil_modulus().unwrap(),
        default.soil_poisson().unwrap(),
        default.contact().unwrap(),
    ];
    let f_default = paper_f(&d, Model::Full, ContactMode::Reciprocal, x);
    assert!(
        f_default < 0.5 * f_est,
        "default optimum has paper f = {f_default}"
    );
    // The high-E basin sits where the soil's compressional speed overtakes the pipe wave
    // (model §7.8 item 3): c_P above ~1250 m/s at the optimum.
    let soil = pipewave::physics::Soil::new(x[0], x[1], 1999.0, 0.0).unwrap();
    assert!(
        soil.wave_speeds().0 > 1250.0,
        "c_P = {}",
        soil.wave_speeds().0
    );
    // A local least-squares polish started at the estimate lowers the objective: not stationary.
    let p = default_problem(&d);
    let x0 = [4.79e7f64.log10(), 0.3326, 0.0];
    let start = p.sum_of_squares(&p.predict(&x0).unwrap());
    let lm = pipewave::optimize::LevenbergMarquardt::new();
    let r = lm.minimize(&p, &x0, Some(&p.bounds().unwrap())).unwrap();
    assert!(
        r.cost < 0.9 * start,
        "polish from the estimate: {start} -> {}",
        r.cost
    );
    eprintln!(
        "polish from the estimate: squared objective {start:.4} -> {:.4}",
        r.cost
    );
    // Deviations (%) of each fit, next to the paper's Table 4 (estimate: Re 2.60/1.85/4.36/5.68,
    // Im 19.12/18.37/13.47/9.06).
    for (name, fit) in [("paper DE", &paper), ("default", &default)] {
        let dev = |f: &dyn Fn(&Measurement, &num_complex::Complex64) -> f64| {
            d.measurements
                .iter()
                .zip(&fit.predicted)
                .map(|(m, k)| format!("{:.2}", f(m, k)))
                .collect::<Vec<_>>()
                .join("/")
        };
        eprintln!(
            "{name}: deviations Re {} %, Im {} %",
            dev(&|m, k| 100.0 * (k.re - m.k_re).abs() / m.k_re),
            dev(&|m, k| 100.0 * (-k.im - m.attenuation).abs() / m.attenuation)
        );
    }
    eprintln!(
        "paper case: f(estimate) = {f_est:.4}; paper DE: E = {:.3e}, nu = {:.3}, xi = {:.2}, f = {:.4}; default: E = {:.3e}, nu = {:.3}, xi = {:.2}, f = {f_default:.4}",
        paper.soil_modulus().unwrap(), paper.soil_poisson().unwrap(), paper.contact().unwrap(), paper.misfit,
        x[0], x[1], x[2]
    );
}

/// The buried MDPE pipe (Muggleton et al. 2004): the raw 100–750 Hz rows binned into 50 Hz
/// bands with standard errors of the mean, fitted with the default method. The fitted soil
/// modulus lies within a factor 1.5 of the soil identified from the group's own model curves
/// (E_m = 4.0e7 Pa, model §3.4) and Re k is explained to within 7 % in every band; but the raw
/// data have structure far beyond their scatter (χ²/dof ≈ 38), which the fit must flag rather
/// than hide. Issue 6 (diagnose) looks for the missing effect.
#[test]
fn mdpe_measurements_fit() {
    let d = pipewave::synth::network::published::muggleton2004()
        .unwrap()
        .segment_data()
        .unwrap();
    assert_eq!(d.measurements.len(), 13);
    assert!((d.pipe.mean_radius - 0.0845).abs() < 1e-12);
    let r = fit_segment(&d, &FitSettings::default(), 1);
    assert_ne!(r.status, FitStatus::Failed, "{:?}", r.message);
    let e = r.soil_modulus().unwrap();
    assert!(e > 4.0e7 / 1.5 && e < 4.0e7 * 1.5, "E = {e}");
    assert!(r.has_flag(FlagCode::HighMisfit));
    assert!(r.chi2_per_dof.unwrap() > 10.0);
    for (m, k) in d.measurements.iter().zip(&r.predicted) {
        assert!(
            (k.re / m.k_re - 1.0).abs() < 0.07,
            "Re k {} vs {}",
            k.re,
            m.k_re
        );
        eprintln!(
            "f {:.0} Re k {:.3} vs {:.3} +- {:.3}; att {:.3} vs {:.3} +- {:.3}",
            m.omega / std::f64::consts::TAU,
            k.re,
            m.k_re,
            m.k_re_std.unwrap(),
            -k.im,
            m.attenuation,
            m.attenuation_std.unwrap()
        );
    }
    eprintln!(
        "MDPE: E = {:.3e} (+- {:?}), nu = {:.3}, xi = {:.2}, chi2/dof = {:?}, flags {}",
        r.soil_modulus().unwrap(),
        r.get(Param::SoilModulus).unwrap().std,
        r.soil_poisson().unwrap(),
        r.contact().unwrap(),
        r.chi2_per_dof,
        r.flag_codes()
    );
}

/// Next to grazing (P44, model §7.8 item 3) the fast search path can follow a root on the
/// other side of the branch cut: at this point of the paper case it gives a misfit of 0.105
/// where the reference path, on which answers are reported, gives 60.3. A start placed there
/// (through the nested start of an extended fit) must not become the answer: the answer is
/// the optimum the reference path rates best, and every optimum checked carries the reference
/// path's misfit. Before issue 10 the fit reported 60.3 here.
#[test]
fn the_answer_is_the_optimum_the_reference_path_rates_best() {
    use pipewave::invert::problem::SolvePath;
    use pipewave::optimize::Objective;
    let d = paper_data();
    let grazing = [7.789145521056639, 0.49668626329253507, 0.0];
    let p = default_problem(&d);
    let sys = p.system_at(&grazing).unwrap();
    let fast = p.value(&grazing);
    let reference = p.sum_of_squares(
        &p.reference_roots(&sys)
            .unwrap()
            .iter()
            .map(|r| r.k1)
            .collect::<Vec<_>>(),
    );
    assert_eq!(p.path, SolvePath::Fast);
    assert!(
        fast < 0.11 && reference > 60.0,
        "fast {fast}, reference {reference}"
    );

    let settings = FitSettings::default();
    let mut base = fit_segment(&d, &settings, 7);
    for (e, v) in base.estimates.iter_mut().zip(grazing) {
        e.value = if e.param == Param::SoilModulus {
            10f64.powf(v)
        } else {
            v
        };
    }
    let r = fit_extended(&d, &settings, 7, &base);
    let best_checked = r
        .restart_misfits
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    assert!(
        r.misfit < 0.19,
        "misfit {} ({:?})",
        r.misfit,
        r.restart_misfits
    );
    assert!(
        (r.misfit - best_checked).abs() <= 1e-9 * r.misfit,
        "misfit {} but the optima rate {:?}",
        r.misfit,
        r.restart_misfits
    );
}

/// In a flat valley the polish creeps. On the bench's synthetic ductile-iron case the data fix
/// c_P and nearly only ξ·c_S; after 30 Levenberg–Marquardt iterations the fit stopped 0.03–0.13
/// in χ² above the valley's bottom on most seeds (85 of 100 before issue 10). The best optimum's
/// polish now goes on while it still descends, so every seed ends where a search with 60×
/// the budget and twice the restarts ends.
#[test]
fn the_best_optimum_is_polished_to_the_bottom_of_a_flat_valley() {
    let d = pipewave::bench::synthetic_iron_data();
    let best = exhaustive_misfit(&d, 0);
    for seed in 1..=6 {
        let r = fit_segment(&d, &FitSettings::default(), seed);
        assert!(
            r.misfit <= best * (1.0 + 1e-6),
            "seed {seed}: misfit {} against the exhaustive search's {best}",
            r.misfit
        );
    }
}

/// On the paper's case the DE runs of seed 15 in (log10 E_m, ν_m) ended on the face ξ = 0,
/// while the global optimum lies at ξ ≈ 0.72 (f 0.183): a polish from the opposite face of
/// ξ's range reached it. Whatever mechanism finds it, the fit from seed 15 reaches the global
/// optimum. The reference is an exhaustive search's answer, so the fit never sees it.
#[test]
fn a_fit_from_a_face_of_the_contact_range_reaches_the_global_optimum() {
    let d = pipewave::bench::paper_case_data();
    let best = exhaustive_misfit(&d, 12345);
    let r = fit_segment(&d, &FitSettings::default(), 15);
    assert!(
        r.misfit <= best * (1.0 + 1e-6),
        "seed 15: misfit {} against the exhaustive search's {best} (restarts {:?})",
        r.misfit,
        r.restart_misfits
    );
}

/// The misfit of a search with 4 restarts of 3,000 evaluations per parameter (60× the default
/// budget, twice its restarts): the reference the default fit is held to.
fn exhaustive_misfit(d: &SegmentData, seed: u64) -> f64 {
    let exhaustive = FitSettings {
        restarts: 4,
        evaluations_per_dimension: 3000,
        ..FitSettings::default()
    };
    fit_segment(d, &exhaustive, seed).misfit
}
