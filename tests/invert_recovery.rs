//! Recovery of known soil parameters from synthetic segments made by the forward model
//! (issue 3): 100 segments across the seven materials, their sizes and six soil classes, with
//! 1 % noise on Re k and 5 % on the attenuation at 4–8 frequencies. The fit sees only the
//! inventory data and the noisy measurements, never the truth. The intervals are tested by
//! their coverage of the truth.

use pipewave::invert::*;
use pipewave::physics::curves::{band_mean, curve, LEAK_BAND_HZ, STANDARD_GRID_HZ};
use pipewave::physics::{ContactMode, Fluid, Model, Soil, System};
use pipewave::synth::{generate, pipe_of, SynthOptions};
use pipewave::types::FitStatus;
use pipewave::units::hz_to_omega;
use rayon::prelude::*;

fn quantile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// What the data determine (issue 9, model §7.10), over 100 synthetic segments: the soil's
/// c_P and c_S inside their 2σ, the true E_m, ν_m and ξ inside their 95 % intervals, for at
/// least 90 % of segments each; c_P within 5 % (median); at least 80 % of fits `ok`, and among
/// those the leak-band speed within 1 % of the truth (90th percentile) and inside its 2σ for at
/// least 90 %; every fitted segment with an interval.
#[test]
fn recovery_over_100_synthetic_segments() {
    let net = generate(&SynthOptions {
        segments: 100,
        seed: 2026,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    });
    assert_eq!(net.len(), 100);
    let fits: Vec<FitResult> = net
        .par_iter()
        .map(|s| fit_segment(&s.segment_data(), &FitSettings::default(), 17))
        .collect();
    let mut speed_err = Vec::new();
    let mut att_err = Vec::new();
    let mut cp_err = Vec::new();
    let mut band_err_ok = Vec::new();
    let (mut n, mut n_ok, mut band_in_ok, mut failed) = (0usize, 0usize, 0usize, 0usize);
    let mut inside = [0usize; 5]; // c_P, c_S, E, ν, ξ
    let mut flag_counts = std::collections::BTreeMap::new();
    for (s, r) in net.iter().zip(&fits) {
        if r.status == FitStatus::Failed {
            failed += 1;
            continue;
        }
        n += 1;
        for f in r.flags.iter().chain(&r.notes) {
            *flag_counts.entry(f.code.as_str()).or_insert(0usize) += 1;
        }
        let (cp, cs) =
            pipewave::physics::soil::soil_speeds(s.soil_modulus, s.soil_poisson, s.soil_density);
        let (fcp, fcs) = (r.p_wave_speed.unwrap(), r.s_wave_speed.unwrap());
        assert!(fcp.std.is_finite() && fcs.std.is_finite(), "{}", s.id);
        cp_err.push((fcp.value / cp - 1.0).abs());
        inside[0] += usize::from((fcp.value - cp).abs() <= 2.0 * fcp.std);
        inside[1] += usize::from((fcs.value - cs).abs() <= 2.0 * fcs.std);
        let truth = [s.soil_modulus, s.soil_poisson, s.contact];
        for (k, p) in [Param::SoilModulus, Param::SoilPoisson, Param::Contact]
            .into_iter()
            .enumerate()
        {
            let e = r.get(p).unwrap();
            assert!(e.interval.lo.is_finite() && e.interval.hi.is_finite() && e.std.is_some());
            assert!(
                e.interval.lo <= e.value && e.value <= e.interval.hi,
                "{}",
                s.id
            );
            inside[2 + k] += usize::from(e.interval.lo <= truth[k] && truth[k] <= e.interval.hi);
        }
        // What the fitted model predicts against the noise-free truth: the figure a
        // correlator uses.
        let truth_sys = System::new(
            Fluid::water(),
            pipe_of(s.material, &s.size),
            Soil::new(s.soil_modulus, s.soil_poisson, s.soil_density, 0.0).unwrap(),
            s.contact,
            Model::Full,
            ContactMode::Reciprocal,
        )
        .unwrap();
        let omegas: Vec<f64> = s
            .measurements
            .iter()
            .map(|m| hz_to_omega(m.frequency_hz))
            .collect();
        let k_true = pipewave::invert::problem::predict(&truth_sys, &omegas).unwrap();
        for (kt, kf) in k_true.iter().zip(&r.predicted) {
            speed_err.push((kt.re / kf.re - 1.0).abs());
            att_err.push((kf.im / kt.im - 1.0).abs());
        }
        if r.status == FitStatus::Ok {
            n_ok += 1;
            let pts: Vec<(f64, Option<f64>)> = curve(&truth_sys, &STANDARD_GRID_HZ)
                .iter()
                .map(|p| (p.frequency_hz, p.status.is_ok().then_some(p.phase_speed)))
                .collect();
            let band_true = band_mean(&pts, LEAK_BAND_HZ).unwrap();
            let b = r.leak_band_speed.unwrap();
            band_err_ok.push((b.value / band_true - 1.0).abs());
            band_in_ok += usize::from((b.value - band_true).abs() <= 2.0 * b.std);
        }
    }
    let frac = |k: usize| inside[k] as f64 / n as f64;
    let cp_med = quantile(&mut cp_err, 0.5);
    let band_p90 = quantile(&mut band_err_ok, 0.9);
    let ok_frac = n_ok as f64 / n as f64;
    let band_cover = band_in_ok as f64 / n_ok as f64;
    let (s_p90, a_med) = (quantile(&mut speed_err, 0.9), quantile(&mut att_err, 0.5));
    eprintln!("recovery, 100 synthetic segments (seed 2026), default method:");
    eprintln!("  failed {failed}; ok {n_ok}/{n}; findings {flag_counts:?}");
    eprintln!(
        "  truth inside: c_P 2σ {:.2}, c_S 2σ {:.2}, E 95 % {:.2}, nu 95 % {:.2}, xi 95 % {:.2}",
        frac(0),
        frac(1),
        frac(2),
        frac(3),
        frac(4)
    );
    eprintln!("  c_P median error {cp_med:.4}");
    eprintln!("  ok fits: leak-band speed p90 error {band_p90:.4}, inside 2σ {band_cover:.2}");
    eprintln!("  predicted phase speed vs truth: p90 error {s_p90:.4}; attenuation median error {a_med:.3}");
    assert!(failed <= 2, "{failed} fits failed");
    for (k, name) in ["c_P", "c_S", "E_m", "nu_m", "xi"].iter().enumerate() {
        assert!(
            frac(k) >= 0.9,
            "{name}: truth inside for only {:.2}",
            frac(k)
        );
    }
    assert!(cp_med <= 0.05, "c_P median error {cp_med}");
    assert!(ok_frac >= 0.8, "only {ok_frac:.2} of fits ok");
    assert!(band_p90 <= 0.01, "leak-band speed p90 error {band_p90}");
    assert!(
        band_cover >= 0.9,
        "leak-band speed inside 2σ for {band_cover:.2}"
    );
    assert!(s_p90 < 0.01, "phase speed p90 error {s_p90}");
    assert!(a_med < 0.05, "attenuation median error {a_med}");
}

/// Nested fits never end worse (issue 16): a fit with an effect switched on contains the base
/// model (the effect at its neutral value), so its misfit is never above the base fit's, over
/// segments with and without that effect hidden in their data.
#[test]
fn an_extended_fit_never_ends_worse_than_its_base() {
    use pipewave::physics::effects::Effect;
    let mut worst = f64::NEG_INFINITY;
    for (effect, seed) in [
        (Effect::WallThinning, 31),
        (Effect::AirInWater, 32),
        (Effect::SoilDamping, 33),
        (Effect::PipeLoss, 34),
    ] {
        let net = generate(&SynthOptions {
            segments: 10,
            seed,
            defect_fraction: 0.0,
            hidden_effect: pipewave::synth::default_hidden_range(effect)
                .map(|(lo, hi)| (effect, lo, hi)),
            hidden_fraction: 0.5,
            ..SynthOptions::default()
        });
        let rows: Vec<(String, f64, f64)> = net
            .par_iter()
            .map(|s| {
                let d = s.segment_data();
                let base = fit_segment(&d, &FitSettings::default(), 3);
                let settings = FitSettings {
                    effects: vec![effect],
                    ..FitSettings::default()
                };
                let ext = fit_extended(&d, &settings, 3, &base);
                (s.id.clone(), base.misfit, ext.misfit)
            })
            .collect();
        for (id, base, ext) in rows {
            worst = worst.max(ext - base);
            assert!(
                ext <= base + 1e-6 * (1.0 + base),
                "{effect}: {id}: extended fit chi2 {ext} above base {base}"
            );
        }
    }
    eprintln!("largest extended minus base chi2: {worst:.3e}");
}

/// The guarantee does not rest on the search: with a DE budget far too small to find the
/// optimum (one restart of 100 evaluations), a plain fit of the extended model ends above the
/// base fit on some segments, and the nested fit on none. The faces and probes find most optima
/// without the DE: since fit algorithm 27 the plain fit ends above the base on 1 of these 120
/// segments (on none of the first 40), so a search that never falls short fails this test.
#[test]
fn the_nested_start_carries_the_guarantee_when_the_search_falls_short() {
    use pipewave::physics::effects::Effect;
    let net = generate(&SynthOptions {
        segments: 120,
        seed: 35,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    });
    let starved = FitSettings {
        effects: vec![Effect::WallThinning],
        restarts: 1,
        evaluations_per_dimension: 1,
        ..FitSettings::default()
    };
    let rows: Vec<(f64, f64, f64)> = net
        .par_iter()
        .map(|s| {
            let d = s.segment_data();
            let base = fit_segment(&d, &FitSettings::default(), 3);
            let plain = fit_segment(&d, &starved, 3);
            let nested = fit_extended(&d, &starved, 3, &base);
            (base.misfit, plain.misfit, nested.misfit)
        })
        .collect();
    let plain_worse = rows
        .iter()
        .filter(|(b, p, _)| *p > b + 1e-3 * (1.0 + b))
        .count();
    eprintln!(
        "starved search: plain extended fit above the base on {plain_worse} of {}",
        rows.len()
    );
    assert!(
        plain_worse > 0,
        "the starved search is not starved: {rows:?}"
    );
    for (b, _, n) in &rows {
        assert!(*n <= b + 1e-6 * (1.0 + b), "nested {n} above base {b}");
    }
}

/// The default method against the paper's on the same synthetic segments: the default's
/// chi-square at its optimum is never worse than at the paper method's optimum (it optimises
/// that objective; the paper's answer is one point of the same space).
#[test]
fn default_never_worse_than_paper_on_its_objective() {
    let net = generate(&SynthOptions {
        segments: 12,
        seed: 99,
        defect_fraction: 0.0,
        ..SynthOptions::default()
    });
    let mut better = 0;
    for s in &net {
        let d = s.segment_data();
        let def = fit_segment(&d, &FitSettings::default(), 5);
        let pap = fit_segment(
            &d,
            &FitSettings::paper(Model::Full, ContactMode::Reciprocal),
            5,
        );
        let p = pipewave::invert::problem::Problem::new(
            &d,
            Method::Default,
            Model::Full,
            ContactMode::Reciprocal,
            &[],
        );
        let chi2_pap = p.sum_of_squares(&pap.predicted);
        assert!(
            def.misfit <= chi2_pap * (1.0 + 1e-6),
            "{}: default {} vs paper {}",
            s.id,
            def.misfit,
            chi2_pap
        );
        if def.misfit < 0.9 * chi2_pap {
            better += 1;
        }
    }
    eprintln!("default clearly better (chi-square 10 % lower) on {better} of 12 segments");
}
