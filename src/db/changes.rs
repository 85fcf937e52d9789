//! What changed between a segment's campaigns (tables `changes` and `campaign_speeds`,
//! migration 0016; model §7.14): the change test of every calibrate fit, and each campaign's
//! leak-band speed fitted on its own.

use rusqlite::{params, Connection, OptionalExtension, Transaction};

use super::DbError;

/// One change-test result (a `changes` row without its id).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChangeRow {
    /// The segment.
    pub segment_id: String,
    /// The calibrate run.
    pub run_id: i64,
    /// The segment's latest campaign (the current state).
    pub campaign: String,
    /// The campaign before it, when there is one.
    pub since_campaign: Option<String>,
    /// `changed`, `unchanged`, `one_campaign` or `untested`.
    pub status: String,
    /// Λ / s² (P94).
    pub statistic: Option<f64>,
    /// Degrees of freedom of its reference χ².
    pub dof: Option<i64>,
    /// Its p-value.
    pub p_value: Option<f64>,
    /// The level it was judged at.
    pub alpha: Option<f64>,
    /// χ² of both campaigns under one state.
    pub chi2_one_state: Option<f64>,
    /// χ² of the earlier campaign fitted on its own.
    pub chi2_earlier: Option<f64>,
    /// χ² of the latest campaign fitted on its own.
    pub chi2_latest: Option<f64>,
    /// The named cause of a change, or `unexplained`.
    pub effect: Option<String>,
    /// Causes the data cannot tell apart from it, comma-separated.
    pub ambiguous_with: String,
    /// The changed quantity before (the earlier campaign's E_m for a soil change; the
    /// effect's neutral value otherwise) …
    pub effect_value_before: Option<f64>,
    /// … and after.
    pub effect_value_after: Option<f64>,
    /// Every cause tried with its χ² and AICc, `; `-separated.
    pub causes: String,
    /// The earlier campaign's fitted soil.
    pub earlier_soil_youngs_modulus_pa: Option<f64>,
    /// Its Poisson's ratio.
    pub earlier_soil_poisson: Option<f64>,
    /// Its contact coefficient.
    pub earlier_contact: Option<f64>,
    /// Change of the leak-band speed from the earlier campaign to the latest, %.
    pub leak_band_speed_pct: Option<f64>,
    /// Its one-sigma error, %.
    pub leak_band_speed_pct_std: Option<f64>,
    /// Whether the current fit pools both campaigns.
    pub pooled: bool,
    /// What the test leaves open, or why it did not run.
    pub note: Option<String>,
}

/// One campaign's leak-band speed, fitted on its own (a `campaign_speeds` row).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CampaignSpeedRow {
    /// The campaign.
    pub campaign: String,
    /// Its newest `measured_on` on this segment.
    pub measured_on: Option<String>,
    /// Leak-band speed, m/s.
    pub leak_band_speed_m_per_s: Option<f64>,
    /// Its one-sigma error, m/s.
    pub leak_band_speed_std_m_per_s: Option<f64>,
    /// χ² of the campaign's own fit.
    pub chi2: Option<f64>,
    /// Its measurements.
    pub n_measurements: i64,
    /// Its fitted soil.
    pub soil_youngs_modulus_pa: Option<f64>,
    /// Its Poisson's ratio.
    pub soil_poisson: Option<f64>,
    /// Its contact coefficient.
    pub contact: Option<f64>,
}

/// What a calibrate fit stores beside the fit: its change test and the campaigns' speeds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChangeRecord {
    /// The change test.
    pub change: ChangeRow,
    /// Each campaign fitted on its own (the latest, and the earlier one tested against it).
    pub speeds: Vec<CampaignSpeedRow>,
}

/// Store `rec` for the fit `fit_id` inside the fit's transaction.
pub(super) fn insert(tx: &Transaction<'_>, fit_id: i64, rec: &ChangeRecord) -> Result<(), DbError> {
    let c = &rec.change;
    tx.prepare_cached(
        "INSERT INTO changes (segment_id, run_id, fit_id, campaign, since_campaign, status, \
         statistic, dof, p_value, alpha, chi2_one_state, chi2_earlier, chi2_latest, effect, \
         ambiguous_with, effect_value_before, effect_value_after, causes, \
         earlier_soil_youngs_modulus_pa, earlier_soil_poisson, earlier_contact, \
         leak_band_speed_pct, leak_band_speed_pct_std, pooled, note) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, \
         ?18, ?19, ?20, ?21, ?22, ?23, ?24, ?25)",
    )?
    .execute(params![
        c.segment_id,
        c.run_id,
        fit_id,
        c.campaign,
        c.since_campaign,
        c.status,
        finite(c.statistic),
        c.dof,
        finite(c.p_value),
        c.alpha,
        finite(c.chi2_one_state),
        finite(c.chi2_earlier),
        finite(c.chi2_latest),
        c.effect,
        c.ambiguous_with,
        finite(c.effect_value_before),
        finite(c.effect_value_after),
        c.causes,
        finite(c.earlier_soil_youngs_modulus_pa),
        finite(c.earlier_soil_poisson),
        finite(c.earlier_contact),
        finite(c.leak_band_speed_pct),
        finite(c.leak_band_speed_pct_std),
        c.pooled,
        c.note,
    ])?;
    let mut ins = tx.prepare_cached(
        "INSERT OR REPLACE INTO campaign_speeds (segment_id, run_id, campaign, measured_on, \
         leak_band_speed_m_per_s, leak_band_speed_std_m_per_s, chi2, n_measurements, \
         soil_youngs_modulus_pa, soil_poisson, contact) \
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)",
    )?;
    for s in &rec.speeds {
        ins.execute(params![
            c.segment_id,
            c.run_id,
            s.campaign,
            s.measured_on,
            finite(s.leak_band_speed_m_per_s),
            finite(s.leak_band_speed_std_m_per_s),
            finite(s.chi2),
            s.n_measurements,
            finite(s.soil_youngs_modulus_pa),
            finite(s.soil_poisson),
            finite(s.contact),
        ])?;
    }
    Ok(())
}

/// A finite number, or NULL.
fn finite(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite())
}

/// The current change finding of a segment (its latest calibrate fit's), if any.
pub fn latest_change(conn: &Connection, segment_id: &str) -> Result<Option<ChangeRow>, DbError> {
    Ok(conn
        .prepare_cached(
            "SELECT segment_id, run_id, campaign, since_campaign, status, statistic, dof, \
             p_value, alpha, chi2_one_state, chi2_earlier, chi2_latest, effect, ambiguous_with, \
             effect_value_before, effect_value_after, causes, earlier_soil_youngs_modulus_pa, \
             earlier_soil_poisson, earlier_contact, leak_band_speed_pct, \
             leak_band_speed_pct_std, pooled, note \
             FROM latest_changes WHERE segment_id = ?1",
        )?
        .query_row([segment_id], |r| {
            Ok(ChangeRow {
                segment_id: r.get(0)?,
                run_id: r.get(1)?,
                campaign: r.get(2)?,
                since_campaign: r.get(3)?,
                status: r.get(4)?,
                statistic: r.get(5)?,
                dof: r.get(6)?,
                p_value: r.get(7)?,
                alpha: r.get(8)?,
                chi2_one_state: r.get(9)?,
                chi2_earlier: r.get(10)?,
                chi2_latest: r.get(11)?,
                effect: r.get(12)?,
                ambiguous_with: r.get(13)?,
                effect_value_before: r.get(14)?,
                effect_value_after: r.get(15)?,
                causes: r.get(16)?,
                earlier_soil_youngs_modulus_pa: r.get(17)?,
                earlier_soil_poisson: r.get(18)?,
                earlier_contact: r.get(19)?,
                leak_band_speed_pct: r.get(20)?,
                leak_band_speed_pct_std: r.get(21)?,
                pooled: r.get(22)?,
                note: r.get(23)?,
            })
        })
        .optional()?)
}

/// A segment's leak-band speed by campaign (view `speed_history`), oldest campaign first (by
/// `measured_on`, then by the order the speeds were stored).
pub fn speed_history(
    conn: &Connection,
    segment_id: &str,
) -> Result<Vec<CampaignSpeedRow>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT s.campaign, s.measured_on, s.leak_band_speed_m_per_s, \
         s.leak_band_speed_std_m_per_s, s.chi2, s.n_measurements \
         FROM speed_history s JOIN campaign_speeds c \
           ON c.segment_id = s.segment_id AND c.campaign = s.campaign AND c.run_id = s.run_id \
         WHERE s.segment_id = ?1 ORDER BY s.measured_on IS NULL, s.measured_on, c.id",
    )?;
    let rows = stmt.query_map([segment_id], |r| {
        Ok(CampaignSpeedRow {
            campaign: r.get(0)?,
            measured_on: r.get(1)?,
            leak_band_speed_m_per_s: r.get(2)?,
            leak_band_speed_std_m_per_s: r.get(3)?,
            chi2: r.get(4)?,
            n_measurements: r.get(5)?,
            ..CampaignSpeedRow::default()
        })
    })?;
    Ok(rows.collect::<Result<_, _>>()?)
}

/// Changes found by the latest calibrate fits, by status and named cause: (status, effect,
/// count), for the run summary and the audit.
pub fn change_counts(conn: &Connection) -> Result<Vec<(String, Option<String>, i64)>, DbError> {
    let mut stmt = conn.prepare_cached(
        "SELECT status, effect, COUNT(*) FROM latest_changes GROUP BY status, effect \
         ORDER BY status, effect",
    )?;
    let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))?;
    Ok(rows.collect::<Result<_, _>>()?)
}
