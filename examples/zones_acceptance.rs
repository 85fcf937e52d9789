//! Issue 12's acceptance figures on a zoned synthetic network: zone E_m and ν_m errors, the
//! coverage of their 95 % intervals, the same for the median of the single fits, an all-metal
//! version of every zone, and the time of the zone estimation against the segment fits.
//!
//! `cargo run --release --example zones_acceptance -- [SEED] [ZONES] [PER_ZONE]`
//! (default 20261122 16 10). Also prints every zone's Cramér–Rao bound against its estimate
//! and what an efficient estimator would reach (`efficient-estimator bound: …`).
//!
//! `cargo run --release --example zones_acceptance -- --bound-only FROM TO [ZONES PER_ZONE]`:
//! only the efficient-estimator line, for the networks of seeds FROM..=TO (not fitted).

use pipewave::synth::zones::{
    estimate, network_bounds, run, zone_bound_at_truth, ZoneCheck, ZonedRun,
};
use pipewave::zones::bound::{pooled_error_quantile, sample_quantile_distribution};
use pipewave::zones::{TAU_E_DECADES, TAU_NU};

fn quantile(v: &[f64], p: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn report(label: &str, zones: &[ZoneCheck]) {
    let e: Vec<f64> = zones.iter().map(|z| z.modulus_error()).collect();
    let n: Vec<f64> = zones.iter().map(|z| z.poisson_error()).collect();
    let se: Vec<f64> = zones
        .iter()
        .map(|z| (z.single_median.0 / z.truth.0 - 1.0).abs())
        .collect();
    let sn: Vec<f64> = zones
        .iter()
        .map(|z| (z.single_median.1 - z.truth.1).abs())
        .collect();
    let cov_e = zones
        .iter()
        .filter(|z| z.estimate.modulus_interval.contains(z.truth.0))
        .count();
    let cov_n = zones
        .iter()
        .filter(|z| z.estimate.poisson_interval.contains(z.truth.1))
        .count();
    println!("{label}: {} zones", zones.len());
    println!(
        "  zone E_m error median {:.1} % p90 {:.1} %; nu_m error median {:.4} p90 {:.4}",
        100.0 * quantile(&e, 0.5),
        100.0 * quantile(&e, 0.9),
        quantile(&n, 0.5),
        quantile(&n, 0.9)
    );
    println!(
        "  single-fit median: E_m error median {:.1} % p90 {:.1} %; nu_m error median {:.4}",
        100.0 * quantile(&se, 0.5),
        100.0 * quantile(&se, 0.9),
        quantile(&sn, 0.5)
    );
    println!(
        "  95 % intervals cover the truth: E_m {}/{}, nu_m {}/{}",
        cov_e,
        zones.len(),
        cov_n,
        zones.len()
    );
    for z in zones {
        let est = &z.estimate;
        println!(
            "  {} ({} metal, {} plastic, {} outliers): E {:.3e} [{:.3e}, {:.3e}] truth {:.3e}; \
             nu {:.3} [{:.3}, {:.3}] truth {:.3}; chi2/dof {:.2}",
            z.zone,
            z.metal,
            z.plastic,
            est.members.iter().filter(|m| m.outlier).count(),
            est.modulus(),
            est.modulus_interval.lo,
            est.modulus_interval.hi,
            z.truth.0,
            est.poisson,
            est.poisson_interval.lo,
            est.poisson_interval.hi,
            z.truth.1,
            est.chi2_per_dof
        );
    }
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("--bound-only") {
        let args: Vec<u64> = std::env::args()
            .skip(2)
            .map(|a| a.parse().expect("FROM TO ZONES PER_ZONE are integers"))
            .collect();
        assert!(args.len() >= 2, "--bound-only FROM TO [ZONES PER_ZONE]");
        bound_only(&args);
        return;
    }
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("SEED ZONES PER_ZONE are integers"))
        .collect();
    let seed = args.first().copied().unwrap_or(20_261_122);
    let zones = args.get(1).copied().unwrap_or(16) as usize;
    let per_zone = args.get(2).copied().unwrap_or(10) as usize;
    let r = run(seed, zones, per_zone);
    report(&format!("seed {seed}, mixed pipes"), &r.zones);
    println!(
        "time: segment fits {:.2} s, zone estimation {:.3} s ({:.1} % of the fits; members' \
         misfit models {:.3} s, zone grids {:.3} s)",
        r.fit_seconds,
        r.zone_seconds,
        100.0 * r.zone_seconds / r.fit_seconds,
        r.member_seconds,
        r.zone_seconds - r.member_seconds
    );
    bounds(&r);
    if std::env::var("ZONES_DEBUG").is_ok() {
        debug(&r);
    }
    let metal = estimate(&r.network, &r.fits, |s| !s.material.is_plastic()).zones;
    report(&format!("seed {seed}, metal pipes only"), &metal);
}

/// The Cramér–Rao bound of every zone (its members' information at their true soils, the
/// scatter of P67 at the generator's values) against the estimate's own 95 % interval, and the
/// E_m error p90 an efficient estimator would reach over these zones.
fn bounds(r: &ZonedRun) {
    let z95 = pipewave::invert::uncertainty::Z_95;
    let mut sds = Vec::new();
    println!("Cramer-Rao bound per zone: sd(ln E) bound / implied by our 95 % interval; sd(nu) bound / ours");
    for z in &r.zones {
        let (b, left_out) = zone_bound_at_truth(&r.network, &r.fits, z, (TAU_E_DECADES, TAU_NU));
        let e = &z.estimate;
        let ours_e = (e.modulus_interval.hi / e.modulus_interval.lo).ln() / (2.0 * z95);
        let ours_nu = (e.poisson_interval.hi - e.poisson_interval.lo) / (2.0 * z95);
        println!(
            "  {} ({} metal, {} plastic{}): sd(ln E) {:.3} / {:.3} (x{:.2}); sd(nu) {:.4} / {:.4}; \
             ln E error {:+.3} ({:+.1} bound sd)",
            z.zone,
            z.metal,
            z.plastic,
            if left_out > 0 { format!(", {left_out} left out") } else { String::new() },
            b.sd_ln_modulus,
            ours_e,
            ours_e / b.sd_ln_modulus,
            b.sd_poisson,
            ours_nu,
            (e.modulus() / z.truth.0).ln(),
            (e.modulus() / z.truth.0).ln() / b.sd_ln_modulus,
        );
        sds.push(b.sd_ln_modulus);
    }
    println!("{}", bound_line(&sds));
}

/// Draws of the efficient estimator's errors for the sample p90's distribution.
const BOUND_DRAWS: usize = 20_000;
/// Issue 12's E_m p90 acceptance threshold.
const P90_TARGET: f64 = 0.15;
/// Issue 12's E_m median acceptance threshold.
const MEDIAN_TARGET: f64 = 0.06;

/// The efficient-estimator line: the pooled p90 and median of |E_est/E_true − 1| for errors
/// at the Cramér–Rao bound of every zone, the median of the sample p90 over this network's
/// zones, and the probability that it is within issue 12's 15 %.
/// (And the same probability for the sample median within 6 %.)
fn bound_line(sds: &[f64]) -> String {
    let (med, pass) = sample_quantile_distribution(sds, 0.9, P90_TARGET, BOUND_DRAWS, 1);
    let (_, pass_median) = sample_quantile_distribution(sds, 0.5, MEDIAN_TARGET, BOUND_DRAWS, 2);
    format!(
        "efficient-estimator bound: E_m error p90 {:.1} % (median {:.1} %) over {} zones; this \
         network's sample p90 median {:.1} %, <= 15 % with probability {:.2} (sample median \
         <= 6 % with probability {:.2})",
        100.0 * pooled_error_quantile(sds, 0.9),
        100.0 * pooled_error_quantile(sds, 0.5),
        sds.len(),
        100.0 * med,
        pass,
        pass_median
    )
}

/// `--bound-only FROM TO [ZONES PER_ZONE]`: the efficient-estimator line for the networks of
/// seeds FROM..=TO, generated but not fitted, and over all their zones pooled.
fn bound_only(args: &[u64]) {
    let (from, to) = (args[0], args[1]);
    let zones = args.get(2).copied().unwrap_or(16) as usize;
    let per_zone = args.get(3).copied().unwrap_or(10) as usize;
    let mut all = Vec::new();
    let mut passes = 0.0;
    for seed in from..=to {
        let b = network_bounds(seed, zones, per_zone, (TAU_E_DECADES, TAU_NU));
        let sds: Vec<f64> = b.iter().map(|(_, b, _)| b.sd_ln_modulus).collect();
        let (_, pass) = sample_quantile_distribution(&sds, 0.9, P90_TARGET, BOUND_DRAWS, 1);
        passes += pass;
        println!("seed {seed}: {}", bound_line(&sds));
        all.extend(sds);
    }
    println!(
        "seeds {from}..={to} ({} networks): {}; mean probability that a network's p90 <= 15 %: {:.2}",
        to - from + 1,
        bound_line(&all),
        passes / (to - from + 1) as f64
    );
}

/// Members of the zones whose E_m is off by more than 20 % (set ZONES_DEBUG=1).
pub fn debug(r: &pipewave::synth::zones::ZonedRun) {
    use pipewave::physics::soil::soil_speeds;
    for z in r.zones.iter().filter(|z| z.modulus_error() > 0.2) {
        println!("zone {}:", z.zone);
        for m in &z.estimate.members {
            let i = r.network.iter().position(|s| s.id == m.segment_id).unwrap();
            let (s, f) = (&r.network[i], &r.fits[i]);
            let d = s.segment_data();
            let setup = pipewave::zones::FitSetup {
                model: f.model,
                contact_mode: f.contact_mode,
                effects: f.effects.clone(),
            };
            let x = pipewave::synth::zones::optimum(f);
            let rstd = [
                f.p_wave_speed.map(|w| w.relative()),
                f.s_wave_speed.map(|w| w.relative()),
            ];
            let mem = pipewave::zones::member_from_fit(&s.id, &d, &setup, &x, rstd).unwrap();
            let (cp, cs) = soil_speeds(s.soil_modulus, s.soil_poisson, s.soil_density);
            let det = mem.info[0] * mem.info[3] - mem.info[1] * mem.info[2];
            let (vp, vs) = (mem.info[3] / det, mem.info[0] / det);
            println!(
                "  {} {:?} fit E {:.3e} nu {:.3} xi {:.2} | truth E {:.3e} nu {:.3} xi {:.2} | dlncP {:+.3} (sd {:.3}) dlncS {:+.3} (sd {:.3}) stat {:.2} {:?}",
                s.id, s.material, 10f64.powf(x[0]), x[1], x[2], s.soil_modulus, s.soil_poisson, s.contact,
                mem.u_hat[0] - cp.ln(), vp.sqrt(), mem.u_hat[1] - cs.ln(), vs.sqrt(), m.statistic, f.status
            );
        }
    }
}
