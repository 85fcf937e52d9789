//! How well a calibration recovered the known soil of a synthetic network: the latest fits
//! against `truth.csv`.
//!
//! What the data determine (model §7.10) is judged over every fitted segment: the relative
//! error of the soil's compressional speed c_P, and how often the truth lies inside the fit's
//! stated uncertainty (c_P and c_S within 2σ, E_m, ν_m and ξ inside their 95 % intervals).
//! The errors of E_m, ν_m and ξ themselves are reported for the fits with status `ok` (median
//! and 90th percentile; `ok` says the *prediction* is trustworthy, not that E_m alone is
//! determined). Flag codes are counted over every fit, and the deliberately defective segments
//! are checked for having been flagged or failed.

use std::collections::{BTreeMap, HashMap};
use std::fmt;

use super::TruthRow;
use crate::db::{FitRow, FitStatus};

/// Median and 90th percentile of a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// Sample size.
    pub n: usize,
    /// Median (NaN for an empty sample).
    pub median: f64,
    /// 90th percentile (NaN for an empty sample).
    pub p90: f64,
}

impl Spread {
    /// Of `values` (NaNs are dropped).
    pub fn of(values: &[f64]) -> Spread {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
        v.sort_by(f64::total_cmp);
        Spread {
            n: v.len(),
            median: quantile(&v, 0.5),
            p90: quantile(&v, 0.9),
        }
    }
}

/// Quantile `p` of sorted values (type 7, [`crate::stats::quantile`]); NaN when empty.
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    crate::stats::quantile(sorted, p).unwrap_or(f64::NAN)
}

/// How the defective segments of one kind were caught.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DefectCatch {
    /// Defective segments with a fit.
    pub n: usize,
    /// Of which flagged or failed.
    pub caught: usize,
}

/// A fit of a segment whose truth is unknown (the published cases), for the report.
#[derive(Debug, Clone, PartialEq)]
pub struct UnknownTruthFit {
    /// Segment.
    pub segment_id: String,
    /// Where the data come from.
    pub source: String,
    /// The fit.
    pub fit: FitRow,
}

/// Fits compared with the truth.
#[derive(Debug, Clone, PartialEq)]
pub struct RecoveryReport {
    /// Rows of truth.csv with a known soil.
    pub n_truth: usize,
    /// Of which with a fit in the database.
    pub n_fitted: usize,
    /// Of those, with status ok / flagged / failed.
    pub n_ok: usize,
    /// Flagged.
    pub n_flagged: usize,
    /// Failed.
    pub n_failed: usize,
    /// |E_fit / E_true − 1| over the unflagged fits.
    pub modulus_rel_err: Spread,
    /// |ν_fit − ν_true| over the unflagged fits.
    pub poisson_abs_err: Spread,
    /// |ξ_fit − ξ_true| over the unflagged fits.
    pub contact_abs_err: Spread,
    /// |E_fit / E_true − 1| over the flagged fits (for comparison: the flags should mark the
    /// poor ones).
    pub modulus_rel_err_flagged: Spread,
    /// Unflagged fits of segments with a deliberate defect (the flags missed them).
    pub unflagged_defective: Vec<String>,
    /// Flag codes over every fit compared (known or unknown truth), with counts.
    pub flag_counts: BTreeMap<String, usize>,
    /// Per defect kind: how many were flagged or failed.
    pub defects: BTreeMap<String, DefectCatch>,
    /// The fits of the segments with unknown truth.
    pub unknown_truth: Vec<UnknownTruthFit>,
    /// |c_P,fit / c_P,true − 1| over the fitted segments (not failed) with a known density.
    pub p_speed_rel_err: Spread,
    /// The same over the fits that state c_P determined (relative one-sigma error at most
    /// [`crate::invert::flags::SPEED_DETERMINED_RSTD`]). Where a nearly incompressible soil
    /// fits as well as the true one (§7.10; the fit's global optimum may be either), c_P is not
    /// determined, the fit says so, and its error there says nothing about the method.
    pub p_speed_rel_err_determined: Spread,
    /// Fitted segments judged for coverage.
    pub n_judged: usize,
    /// Of those, with the truth inside: c_P ± 2σ, c_S ± 2σ, the 95 % intervals of E_m, ν_m, ξ.
    pub inside: [usize; 5],
}

impl RecoveryReport {
    /// Fraction of the judged segments with the truth inside, per quantity (order of
    /// [`RecoveryReport::inside`]).
    pub fn coverage(&self) -> [f64; 5] {
        self.inside.map(|k| k as f64 / self.n_judged.max(1) as f64)
    }
}

/// Compare the latest fits with the truth. Fits of segments not in `truth` are ignored; truth
/// rows without a fit count in `n_truth` only.
///
/// `soil_density` gives each segment's soil density (kg/m³), needed for the true soil speeds.
pub fn compare(
    fits: &[FitRow],
    truth: &[TruthRow],
    soil_density: &HashMap<String, f64>,
) -> RecoveryReport {
    let by_id: HashMap<&str, &FitRow> = fits.iter().map(|f| (f.segment_id.as_str(), f)).collect();
    let mut r = RecoveryReport {
        n_truth: 0,
        n_fitted: 0,
        n_ok: 0,
        n_flagged: 0,
        n_failed: 0,
        modulus_rel_err: Spread::of(&[]),
        poisson_abs_err: Spread::of(&[]),
        contact_abs_err: Spread::of(&[]),
        modulus_rel_err_flagged: Spread::of(&[]),
        unflagged_defective: Vec::new(),
        flag_counts: BTreeMap::new(),
        defects: BTreeMap::new(),
        unknown_truth: Vec::new(),
        p_speed_rel_err: Spread::of(&[]),
        p_speed_rel_err_determined: Spread::of(&[]),
        n_judged: 0,
        inside: [0; 5],
    };
    let (mut cp_err, mut cp_err_determined) = (Vec::new(), Vec::new());
    let (mut e_ok, mut nu_ok, mut xi_ok, mut e_flagged) = (vec![], vec![], vec![], vec![]);
    for t in truth {
        let fit = by_id.get(t.segment_id.as_str()).copied();
        if let Some(f) = fit {
            for code in f.flags.split(',').filter(|c| !c.is_empty()) {
                *r.flag_counts.entry(code.to_string()).or_insert(0) += 1;
            }
        }
        let Some(e_true) = t.soil_youngs_modulus_pa else {
            if let Some(f) = fit {
                r.unknown_truth.push(UnknownTruthFit {
                    segment_id: t.segment_id.clone(),
                    source: t.source.clone(),
                    fit: f.clone(),
                });
            }
            continue;
        };
        r.n_truth += 1;
        let Some(f) = fit else { continue };
        r.n_fitted += 1;
        let rel_e = f.soil_youngs_modulus_pa.map(|e| (e / e_true - 1.0).abs());
        if let (Some(nu), Some(xi), Some(&rho), true) = (
            t.soil_poisson,
            t.contact,
            soil_density.get(&t.segment_id),
            f.status != FitStatus::Failed,
        ) {
            let (cp, cs) = crate::physics::soil::soil_speeds(e_true, nu, rho);
            let within = |v: Option<f64>, s: Option<f64>, truth: f64| matches!((v, s), (Some(v), Some(s)) if (v - truth).abs() <= 2.0 * s);
            let between = |lo: Option<f64>, hi: Option<f64>, truth: f64| matches!((lo, hi), (Some(lo), Some(hi)) if lo <= truth && truth <= hi);
            if let Some(v) = f.soil_p_wave_speed_m_per_s {
                let err = (v / cp - 1.0).abs();
                cp_err.push(err);
                if f.soil_p_wave_speed_std_m_per_s
                    .is_some_and(|s| s <= crate::invert::flags::SPEED_DETERMINED_RSTD * v.abs())
                {
                    cp_err_determined.push(err);
                }
            }
            r.n_judged += 1;
            let hits = [
                within(
                    f.soil_p_wave_speed_m_per_s,
                    f.soil_p_wave_speed_std_m_per_s,
                    cp,
                ),
                within(
                    f.soil_s_wave_speed_m_per_s,
                    f.soil_s_wave_speed_std_m_per_s,
                    cs,
                ),
                between(
                    f.soil_youngs_modulus_lo_pa,
                    f.soil_youngs_modulus_hi_pa,
                    e_true,
                ),
                between(f.soil_poisson_lo, f.soil_poisson_hi, nu),
                between(f.contact_lo, f.contact_hi, xi),
            ];
            for (k, h) in hits.into_iter().enumerate() {
                r.inside[k] += usize::from(h);
            }
        }
        match f.status {
            FitStatus::Ok => {
                r.n_ok += 1;
                e_ok.extend(rel_e);
                if let (Some(a), Some(b)) = (f.soil_poisson, t.soil_poisson) {
                    nu_ok.push((a - b).abs());
                }
                if let (Some(a), Some(b)) = (f.contact, t.contact) {
                    xi_ok.push((a - b).abs());
                }
            }
            FitStatus::Flagged => {
                r.n_flagged += 1;
                e_flagged.extend(rel_e);
            }
            FitStatus::Failed => r.n_failed += 1,
        }
        if let Some(d) = &t.defect {
            let c = r.defects.entry(d.clone()).or_default();
            c.n += 1;
            if f.status == FitStatus::Ok {
                r.unflagged_defective.push(t.segment_id.clone());
            } else {
                c.caught += 1;
            }
        }
    }
    r.modulus_rel_err = Spread::of(&e_ok);
    r.poisson_abs_err = Spread::of(&nu_ok);
    r.contact_abs_err = Spread::of(&xi_ok);
    r.modulus_rel_err_flagged = Spread::of(&e_flagged);
    r.p_speed_rel_err = Spread::of(&cp_err);
    r.p_speed_rel_err_determined = Spread::of(&cp_err_determined);
    r
}

/// Each segment's soil density from the inventory, kg/m³, by id.
pub fn soil_densities(
    conn: &rusqlite::Connection,
) -> Result<HashMap<String, f64>, crate::db::DbError> {
    Ok(crate::db::load_segments(conn, None)?
        .into_iter()
        .map(|s| (s.segment_id, s.soil_density_kg_m3))
        .collect())
}

fn pct(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * x)
    }
}

fn num(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.3}")
    }
}

impl fmt::Display for RecoveryReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "recovery: {} synthetic segments, {} fitted: {} ok, {} flagged, {} failed",
            self.n_truth, self.n_fitted, self.n_ok, self.n_flagged, self.n_failed
        )?;
        let c = self.coverage();
        writeln!(
            f,
            "  what the data determine (n = {}): c_P rel. error median {}, p90 {} (where the fit \
             states c_P determined, n = {}: median {}, p90 {}); truth inside c_P ± 2σ {}, c_S ± 2σ \
             {}, 95 % intervals of E {}, nu {}, xi {}",
            self.n_judged,
            pct(self.p_speed_rel_err.median),
            pct(self.p_speed_rel_err.p90),
            self.p_speed_rel_err_determined.n,
            pct(self.p_speed_rel_err_determined.median),
            pct(self.p_speed_rel_err_determined.p90),
            pct(c[0]),
            pct(c[1]),
            pct(c[2]),
            pct(c[3]),
            pct(c[4]),
        )?;
        writeln!(
            f,
            "  ok fits (n = {}):  E rel. error median {}, p90 {};  nu abs. error median \
             {}, p90 {};  xi abs. error median {}, p90 {}",
            self.modulus_rel_err.n,
            pct(self.modulus_rel_err.median),
            pct(self.modulus_rel_err.p90),
            num(self.poisson_abs_err.median),
            num(self.poisson_abs_err.p90),
            num(self.contact_abs_err.median),
            num(self.contact_abs_err.p90),
        )?;
        writeln!(
            f,
            "  flagged fits (n = {}):  E rel. error median {}, p90 {}",
            self.modulus_rel_err_flagged.n,
            pct(self.modulus_rel_err_flagged.median),
            pct(self.modulus_rel_err_flagged.p90),
        )?;
        let flags: Vec<String> = self
            .flag_counts
            .iter()
            .map(|(c, n)| format!("{c} {n}"))
            .collect();
        writeln!(
            f,
            "  flags: {}",
            if flags.is_empty() {
                "none".to_string()
            } else {
                flags.join(", ")
            }
        )?;
        let defects: Vec<String> = self
            .defects
            .iter()
            .map(|(d, c)| format!("{d} {}/{}", c.caught, c.n))
            .collect();
        writeln!(
            f,
            "  defective segments flagged or failed: {}{}",
            if defects.is_empty() {
                "none in the network".to_string()
            } else {
                defects.join(", ")
            },
            if self.unflagged_defective.is_empty() {
                String::new()
            } else {
                format!("; missed: {}", self.unflagged_defective.join(", "))
            }
        )?;
        for u in &self.unknown_truth {
            let g = |v: Option<f64>| v.map(|x| format!("{x:.4}")).unwrap_or("-".into());
            writeln!(
                f,
                "  {} ({}): {}, E = {}, nu = {}, xi = {}, chi2/dof = {}, flags: {}",
                u.segment_id,
                u.source,
                u.fit.status,
                u.fit
                    .soil_youngs_modulus_pa
                    .map(|e| format!("{e:.3e} Pa"))
                    .unwrap_or("-".into()),
                g(u.fit.soil_poisson),
                g(u.fit.contact),
                g(u.fit.chi2_per_dof),
                if u.fit.flags.is_empty() {
                    "none"
                } else {
                    &u.fit.flags
                }
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{ContactMode, Model};

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert!((quantile(&v, 0.9) - 4.6).abs() < 1e-12);
        assert_eq!(quantile(&[7.0], 0.9), 7.0);
        assert!(quantile(&[], 0.5).is_nan());
        let s = Spread::of(&[4.0, f64::NAN, 1.0, 3.0, 2.0]);
        assert_eq!((s.n, s.median), (4, 2.5));
    }

    fn truth(id: &str, e: f64, defect: Option<&str>) -> TruthRow {
        TruthRow {
            soil_youngs_modulus_pa: Some(e),
            soil_poisson: Some(0.3),
            contact: Some(0.5),
            defect: defect.map(str::to_string),
            ..TruthRow::unknown(id, "synthetic")
        }
    }

    fn fit(id: &str, status: FitStatus, e: f64, flags: &str) -> FitRow {
        let mut f = FitRow::new(id, 1, status, Model::Full, ContactMode::Reciprocal);
        f.soil_youngs_modulus_pa = Some(e);
        f.soil_poisson = Some(0.35);
        f.contact = Some(0.4);
        f.flags = flags.into();
        f
    }

    #[test]
    fn compare_splits_by_status_and_counts_flags_and_defects() {
        let truth = vec![
            truth("A", 1e7, None),
            truth("B", 1e7, None),
            truth("C", 1e7, Some("outlier")),
            truth("D", 1e7, Some("wrong_material")),
            truth("E", 1e7, None),
            TruthRow::unknown("REAL", "published: x"),
        ];
        let fits = vec![
            fit("A", FitStatus::Ok, 1.1e7, ""),
            fit("B", FitStatus::Ok, 0.8e7, ""),
            fit("C", FitStatus::Flagged, 3e7, "high_misfit,at_bound"),
            fit("D", FitStatus::Ok, 1e7, ""),
            fit("REAL", FitStatus::Flagged, 5e7, "high_misfit"),
            fit("OTHER", FitStatus::Ok, 1.0, ""),
        ];
        let r = compare(&fits, &truth, &HashMap::new());
        assert_eq!((r.n_truth, r.n_fitted), (5, 4));
        assert_eq!((r.n_ok, r.n_flagged, r.n_failed), (3, 1, 0));
        // Unflagged E errors: 0.1, 0.2, 0.0.
        assert_eq!(r.modulus_rel_err.n, 3);
        assert!((r.modulus_rel_err.median - 0.1).abs() < 1e-12);
        assert!((r.poisson_abs_err.median - 0.05).abs() < 1e-12);
        assert!((r.contact_abs_err.p90 - 0.1).abs() < 1e-12);
        assert!((r.modulus_rel_err_flagged.median - 2.0).abs() < 1e-12);
        assert_eq!(r.flag_counts["high_misfit"], 2);
        assert_eq!(r.flag_counts["at_bound"], 1);
        assert_eq!(r.defects["outlier"], DefectCatch { n: 1, caught: 1 });
        assert_eq!(r.defects["wrong_material"], DefectCatch { n: 1, caught: 0 });
        assert_eq!(r.unflagged_defective, vec!["D".to_string()]);
        assert_eq!(r.unknown_truth.len(), 1);
        let text = r.to_string();
        assert!(text.contains("E rel. error median 10.0 %"), "{text}");
        assert!(text.contains("REAL (published: x): flagged"), "{text}");
    }
}
