//! The per-segment record of the exports and the audit report, assembled in one place: the
//! inventory row, its latest fit (view `latest_fits`), that fit's curve (same run), the speeds
//! and attenuations at the standard frequencies and the leak-band mean speed. [`Records`] reads
//! them from the database a page at a time, for the writers to stream.
//!
//! [`PROPERTIES`] (module `columns`) lists the exported properties, in order, with their types: the GeoPackage
//! columns, the GeoJSON properties and the CSV columns are all made from it, so the three
//! formats cannot drift apart.

use crate::db::wkt::LineString;
use crate::db::{self, pages, CurvePoint, Database, FitRow, SegmentRecord};
use crate::physics::curves::{band_mean, LEAK_BAND_HZ};

use super::ExportError;
use crate::db::crs;

pub use super::columns::{speed_by_campaign, Kind, Property, Value, PROPERTIES};

/// The standard export frequencies, Hz. All are on
/// [`STANDARD_GRID_HZ`](crate::physics::curves::STANDARD_GRID_HZ), so the values are stored
/// curve points, not interpolations.
pub const EXPORT_FREQUENCIES_HZ: [f64; 4] = [100.0, 200.0, 500.0, 1000.0];

/// Relative tolerance for matching a stored curve frequency to a wanted one (the grid is stored
/// as written in the source, so equal values match exactly; this only absorbs round-off of a
/// curve written through another tool).
pub const FREQUENCY_MATCH_REL_TOL: f64 = 1e-9;

/// The status exported for a segment without any fit.
pub const UNFITTED: &str = "unfitted";

/// One segment as exported.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentExport {
    /// The inventory row, with its measurements.
    pub segment: SegmentRecord,
    /// The parsed geometry, in EPSG:`segment.srid` (None: no geometry, or unreadable).
    pub geometry: Option<LineString>,
    /// The latest fit (None: never fitted).
    pub fit: Option<FitRow>,
    /// The latest fit's curve, by increasing frequency.
    pub curve: Vec<CurvePoint>,
    /// Phase speed at [`EXPORT_FREQUENCIES_HZ`], m/s.
    pub speed_at: [Option<f64>; 4],
    /// Attenuation at [`EXPORT_FREQUENCIES_HZ`], dB/m.
    pub attenuation_at: [Option<f64>; 4],
    /// Mean phase speed over [`LEAK_BAND_HZ`], m/s ([`band_mean_speed`]).
    pub leak_band_speed: Option<f64>,
    /// Its zone's newest estimate and its place in it (model §7.11), if any
    /// ([`Self::set_zone`]).
    pub zone: Option<(db::zones::ZoneFitRow, db::zones::ZoneMemberRow)>,
    /// The latest fit's `flags`, with its zone's verdict on that fit appended
    /// ([`crate::zones::segment_flag`]: `zone_outlier`); `None` when never fitted. What the
    /// exports and the audit report show as the segment's flags.
    pub flags: Option<String>,
    /// The reason lines of [`Self::flags`], one per flag.
    pub flag_reasons: Option<String>,
    /// The soil field's prediction (physics P81), for a segment without a fitted speed.
    pub prediction: Option<db::field::PredictionRow>,
    /// The segment as the latest field update saw it: its class, its leave-one-out check.
    pub field: Option<db::field::FieldSegmentRow>,
    /// Where the exported speed comes from: [`SPEED_FITTED`], [`SPEED_PREDICTED`] or
    /// [`SPEED_NONE`].
    pub speed_source: &'static str,
    /// Why, in words (what a prediction rests on, why there is no speed).
    pub speed_source_reason: String,
    /// The change test of the latest calibrate fit (model §7.14; view `latest_changes`).
    pub change: Option<db::changes::ChangeRow>,
    /// The leak-band speed of each campaign fitted on its own, oldest first (view
    /// `speed_history`).
    pub speed_history: Vec<db::changes::CampaignSpeedRow>,
    /// [`Self::speed_history`] as one line ([`speed_by_campaign`]).
    pub speed_by_campaign: Option<String>,
}

/// `speed_source` of a segment whose speed is its own fit's.
pub const SPEED_FITTED: &str = "fitted";
/// `speed_source` of a segment whose speed the soil field predicts (physics P81).
pub const SPEED_PREDICTED: &str = "predicted";
/// `speed_source` of a segment without a speed.
pub const SPEED_NONE: &str = "none";

impl SegmentExport {
    /// Build the record from its parts (the derived values are computed here).
    pub fn new(segment: SegmentRecord, mut fit: Option<FitRow>, curve: Vec<CurvePoint>) -> Self {
        // Reasons are stored one per line; every export gives them on one line, `; `-joined.
        if let Some(f) = fit.as_mut() {
            f.flag_reasons = crate::spreadsheet::one_line(&f.flag_reasons).into_owned();
            f.note_reasons = crate::spreadsheet::one_line(&f.note_reasons).into_owned();
        }
        let geometry = segment
            .geometry_wkt
            .as_deref()
            .and_then(|w| crs::usable_line(w, segment.srid).ok());
        let mut speed_at = [None; 4];
        let mut attenuation_at = [None; 4];
        for (i, &f) in EXPORT_FREQUENCIES_HZ.iter().enumerate() {
            if let Some(p) = point_at(&curve, f) {
                speed_at[i] = p.phase_speed_m_per_s.filter(|v| v.is_finite());
                // Never an attenuation below 0 (a curve stored by an older version may hold one
                // where its correction ran away).
                attenuation_at[i] = p
                    .attenuation_db_per_m
                    .filter(|v| v.is_finite() && *v >= 0.0);
            }
        }
        let leak_band_speed = band_mean_speed(&curve, LEAK_BAND_HZ);
        SegmentExport {
            segment,
            geometry,
            curve,
            speed_at,
            attenuation_at,
            leak_band_speed,
            flags: fit.as_ref().map(|f| f.flags.clone()),
            flag_reasons: fit.as_ref().map(|f| f.flag_reasons.clone()),
            fit,
            zone: None,
            prediction: None,
            field: None,
            speed_source: SPEED_NONE,
            speed_source_reason: String::new(),
            change: None,
            speed_history: Vec::new(),
            speed_by_campaign: None,
        }
        .settled()
    }

    /// Whether the latest fit gives the segment a speed.
    fn has_fitted_speed(&self) -> bool {
        self.fit
            .as_ref()
            .is_some_and(|f| f.status != db::FitStatus::Failed)
            && self.leak_band_speed.is_some()
    }

    /// Set [`Self::speed_source`] and its reason from the fit, prediction and field row. A
    /// prediction is attached only where the fit gave no speed ([`Self::set_field`]), so it
    /// decides first: the speed is then the prediction's even though a fit is kept.
    fn settled(mut self) -> Self {
        let (source, reason) = if let Some(p) = &self.prediction {
            let reason = match &self.fit {
                Some(f) if f.status != db::FitStatus::Failed => format!(
                    "its fit gives no leak-band speed; the soil field's: {}",
                    p.note
                ),
                _ => p.note.clone(),
            };
            (SPEED_PREDICTED, reason)
        } else if self.has_fitted_speed() {
            let n = self
                .fit
                .as_ref()
                .and_then(|f| f.n_measurements)
                .unwrap_or(0);
            (SPEED_FITTED, format!("fitted to {n} measurements"))
        } else if let Some(f) = self.field.as_ref().filter(|f| !f.note.is_empty()) {
            (SPEED_NONE, f.note.clone())
        } else if let Some(msg) = self.fit.as_ref().and_then(|f| f.message.clone()) {
            (
                SPEED_NONE,
                format!("the fit failed ({msg}) and the soil field has not been updated since"),
            )
        } else {
            (
                SPEED_NONE,
                "no fit and no soil-field prediction: run calibrate".to_string(),
            )
        };
        self.speed_source = source;
        self.speed_source_reason = reason;
        self
    }

    /// Attach the soil field's view of the segment and, when it has no fitted speed, its
    /// prediction (whose curve then stands for the fit's); a `field_outlier` is appended to
    /// [`Self::flags`].
    pub fn set_field(
        mut self,
        field: Option<db::field::FieldSegmentRow>,
        prediction: Option<db::field::Prediction>,
    ) -> Self {
        if !self.has_fitted_speed() {
            if let Some((p, curve)) = prediction {
                let fit = self.fit.take();
                let flags = (self.flags.take(), self.flag_reasons.take());
                let zone = self.zone.take();
                let mut rec = SegmentExport::new(self.segment, fit, curve);
                rec.leak_band_speed = p.leak_band_speed.map(|v| v.0).or(rec.leak_band_speed);
                (rec.flags, rec.flag_reasons) = flags;
                rec.zone = zone;
                rec.prediction = Some(p);
                self = rec;
            }
        }
        if let Some(f) = field.as_ref().filter(|f| f.field_outlier) {
            let z = f.loo_z.unwrap_or(f64::NAN);
            let reason = format!(
                "field_outlier: its leak-band speed is {z:.1} sigma from what its neighbours \
                 predict (leave-one-out, |z| > {:.2}): a wrong record, a changed soil or a leak",
                crate::field::FIELD_OUTLIER_Z
            );
            let join = |list: Option<String>, item: &str, sep: &str| match list {
                Some(l) if !l.is_empty() => Some(format!("{l}{sep}{item}")),
                _ => Some(item.to_string()),
            };
            self.flags = join(self.flags.take(), "field_outlier", ",");
            self.flag_reasons = join(self.flag_reasons.take(), &reason, "; ");
        }
        self.field = field;
        self.settled()
    }

    /// One-sigma error of the exported leak-band speed: the fit's, or the prediction's.
    pub fn leak_band_speed_std(&self) -> Option<f64> {
        match self.speed_source {
            SPEED_FITTED => self
                .fit
                .as_ref()
                .and_then(|f| f.leak_band_speed_std_m_per_s),
            SPEED_PREDICTED => self
                .prediction
                .as_ref()
                .and_then(|p| p.leak_band_speed.map(|v| v.1)),
            _ => None,
        }
    }

    /// Attach the segment's zone estimate and membership, and append the zone's verdict on the
    /// latest fit to [`Self::flags`] and [`Self::flag_reasons`].
    pub fn set_zone(&mut self, zone: Option<(db::zones::ZoneFitRow, db::zones::ZoneMemberRow)>) {
        self.zone = zone;
        let (Some(fit), Some((z, m))) = (&self.fit, &self.zone) else {
            return;
        };
        if let Some((flag, reason)) =
            crate::zones::segment_flag(z, m, fit, self.segment.soil_density_kg_m3)
        {
            let join = |list: &str, item: &str, sep: &str| {
                if list.is_empty() {
                    item.to_string()
                } else {
                    format!("{list}{sep}{item}")
                }
            };
            self.flags = Some(join(&fit.flags, flag.as_str(), ","));
            self.flag_reasons = Some(join(&fit.flag_reasons, &reason, "; "));
        }
    }

    /// The segment id.
    pub fn id(&self) -> &str {
        &self.segment.segment_id
    }

    /// `ok`, `flagged`, `failed`, or [`UNFITTED`].
    pub fn status(&self) -> &'static str {
        self.fit.as_ref().map_or(UNFITTED, |f| f.status.as_str())
    }

    /// The flag codes of the latest fit and its zone's verdict (empty when none or unfitted).
    pub fn flag_codes(&self) -> impl Iterator<Item = &str> {
        self.flags
            .iter()
            .flat_map(|f| f.split(','))
            .map(str::trim)
            .filter(|s| !s.is_empty())
    }
}

/// The stored point at frequency `f_hz`, if the curve has one.
fn point_at(curve: &[CurvePoint], f_hz: f64) -> Option<&CurvePoint> {
    curve
        .iter()
        .find(|p| (p.frequency_hz - f_hz).abs() <= FREQUENCY_MATCH_REL_TOL * f_hz)
}

/// Mean phase speed over a band of a stored curve, m/s ([`band_mean`], which says when it is
/// `None`).
pub fn band_mean_speed(curve: &[CurvePoint], band_hz: (f64, f64)) -> Option<f64> {
    let pts: Vec<(f64, Option<f64>)> = curve
        .iter()
        .map(|p| (p.frequency_hz, p.phase_speed_m_per_s))
        .collect();
    band_mean(&pts, band_hz)
}

/// Segments the exports and the audit report read from the database at a time: a page holds
/// this many records with their measurements and curves (about 9 kB each, so about 2 MB), so
/// what they hold does not grow with the network.
pub const PAGE_SIZE: usize = 256;

/// The records of a database, read a page of [`Records::page_size`] segments at a time in id
/// order: every segment of the inventory with its latest fit, that fit's curve and its zone.
/// Segments without a fit are included (status [`UNFITTED`]). Each writer walks them once or
/// twice ([`Records::for_each`], [`Records::dominant_srid`]) inside one read transaction
/// ([`Records::snapshot`]), so every pass sees the same database.
#[derive(Debug, Clone, Copy)]
pub struct Records<'a> {
    db: &'a Database,
    page_size: usize,
}

impl<'a> Records<'a> {
    /// The records of `db`, read `page_size` segments at a time (at least one).
    pub fn new(db: &'a Database, page_size: usize) -> Self {
        Records {
            db,
            page_size: page_size.max(1),
        }
    }

    /// The database.
    pub fn db(&self) -> &'a Database {
        self.db
    }

    /// Segments read per page.
    pub fn page_size(&self) -> usize {
        self.page_size
    }

    /// Start a read transaction, so the passes of one export see one state of the database even
    /// while a calibrate run stores fits (WAL: the run is not blocked). `None` when the caller
    /// is already in a transaction. Rolled back (nothing was written) when dropped.
    pub fn snapshot(&self) -> Result<Option<rusqlite::Transaction<'a>>, ExportError> {
        let conn = self.db.conn();
        if !conn.is_autocommit() {
            return Ok(None);
        }
        let tx = conn
            .unchecked_transaction()
            .map_err(|e| ExportError::db(self.db)(e.into()))?;
        // The snapshot begins at the first read.
        tx.query_row("SELECT COUNT(*) FROM sqlite_master", [], |r| {
            r.get::<_, i64>(0)
        })
        .map_err(|e| ExportError::db(self.db)(e.into()))?;
        Ok(Some(tx))
    }

    /// Call `f` on every record in id order, a page at a time. A stored geometry that cannot
    /// be parsed is passed without geometry, with a warning in `warnings`.
    pub fn for_each(
        &self,
        warnings: &mut Vec<String>,
        mut f: impl FnMut(SegmentExport) -> Result<(), ExportError>,
    ) -> Result<(), ExportError> {
        let conn = self.db.conn();
        let err = ExportError::db(self.db);
        let zones = db::zones::latest_zone_fits(conn).map_err(&err)?;
        let mut after: Option<String> = None;
        loop {
            let page =
                pages::segments_page(conn, after.as_deref(), self.page_size).map_err(&err)?;
            let (Some(first), Some(last)) = (page.first(), page.last()) else {
                break;
            };
            let mut members =
                pages::zone_memberships_between(conn, &zones, &first.segment_id, &last.segment_id)
                    .map_err(&err)?;
            let full = page.len() >= self.page_size;
            after = Some(last.segment_id.clone());
            for seg in page {
                let zone = members.remove(&seg.segment_id);
                f(self.assemble(seg, zone, warnings)?)?;
            }
            if !full {
                break;
            }
        }
        Ok(())
    }

    /// One segment's record, or `None` when it is not in the inventory.
    pub fn load(
        &self,
        segment_id: &str,
        warnings: &mut Vec<String>,
    ) -> Result<Option<SegmentExport>, ExportError> {
        let conn = self.db.conn();
        let err = ExportError::db(self.db);
        let Some(seg) = db::load_segment(conn, segment_id).map_err(&err)? else {
            return Ok(None);
        };
        let zones = db::zones::latest_zone_fits(conn).map_err(&err)?;
        let zone = pages::zone_memberships_between(conn, &zones, segment_id, segment_id)
            .map_err(&err)?
            .remove(segment_id);
        self.assemble(seg, zone, warnings).map(Some)
    }

    /// The record of one segment row: its latest fit, that fit's curve, its zone.
    fn assemble(
        &self,
        seg: SegmentRecord,
        zone: Option<(db::zones::ZoneFitRow, db::zones::ZoneMemberRow)>,
        warnings: &mut Vec<String>,
    ) -> Result<SegmentExport, ExportError> {
        let conn = self.db.conn();
        let err = ExportError::db(self.db);
        let fit = db::latest_fits(conn, Some(std::slice::from_ref(&seg.segment_id)))
            .map_err(&err)?
            .pop();
        let curve = match &fit {
            Some(f) => db::curves_for(conn, &f.segment_id, f.run_id).map_err(&err)?,
            None => Vec::new(),
        };
        let mut rec = SegmentExport::new(seg, fit, curve);
        rec.set_zone(zone);
        let id = rec.segment.segment_id.clone();
        let field = db::field::field_segment(conn, &id).map_err(&err)?;
        let prediction = db::field::prediction_for(conn, &id).map_err(&err)?;
        let mut rec = rec.set_field(field, prediction);
        rec.change = db::changes::latest_change(conn, &id).map_err(&err)?;
        rec.speed_history = db::changes::speed_history(conn, &id).map_err(&err)?;
        rec.speed_by_campaign = speed_by_campaign(&rec.speed_history);
        if let (Some(w), None) = (&rec.segment.geometry_wkt, &rec.geometry) {
            let why = crs::usable_line(w, rec.segment.srid)
                .err()
                .unwrap_or_default();
            warnings.push(format!(
                "segment {}: its stored geometry cannot be read ({why}); exported without geometry",
                rec.id()
            ));
        }
        Ok(rec)
    }

    /// The coordinate system most segments' readable geometries are in
    /// ([`crs::dominant_srid`]), from one pass over the geometries alone; `None` when no
    /// segment has a readable geometry with a system.
    pub fn dominant_srid(&self) -> Result<Option<i64>, ExportError> {
        let mut srids = std::collections::BTreeMap::<i64, usize>::new();
        pages::for_each_geometry(self.db.conn(), |g| {
            if let (Some(w), Some(srid)) = (g.geometry_wkt.as_deref(), g.srid) {
                if crs::usable_line(w, Some(srid)).is_ok() {
                    *srids.entry(srid).or_default() += 1;
                }
            }
            Ok::<(), db::DbError>(())
        })
        .map_err(ExportError::db(self.db))?;
        Ok(crs::dominant_of_counts(srids))
    }
}

/// Every segment of the inventory, sorted by id, with its latest fit and that fit's curve
/// ([`Records::for_each`] collected: for small databases and tests; the exports stream).
pub fn load_records(
    db: &Database,
    warnings: &mut Vec<String>,
) -> Result<Vec<SegmentExport>, ExportError> {
    let mut out = Vec::new();
    Records::new(db, PAGE_SIZE).for_each(warnings, |r| {
        out.push(r);
        Ok(())
    })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::curves::STANDARD_GRID_HZ;

    fn curve(c: impl Fn(f64) -> Option<f64>) -> Vec<CurvePoint> {
        STANDARD_GRID_HZ
            .iter()
            .map(|&f| CurvePoint {
                frequency_hz: f,
                phase_speed_m_per_s: c(f),
                attenuation_db_per_m: Some(f * 1e-4),
                phase_speed_std_m_per_s: None,
                attenuation_std_db_per_m: None,
                model_phase_speed_m_per_s: None,
                model_attenuation_db_per_m: None,
            })
            .collect()
    }

    /// A fitted segment whose curve has no leak-band mean (its wave ends inside the band) takes
    /// the soil field's prediction: its speed, error and source are the prediction's, not
    /// labelled as fitted with no error.
    #[test]
    fn a_fit_without_a_band_speed_exports_the_prediction_as_predicted() {
        let segment =
            SegmentRecord::new("P-1", crate::physics::Material::Hdpe, 250.0, 14.8, 2065.0);
        let fit = db::FitRow::new(
            "P-1",
            1,
            db::FitStatus::Flagged,
            crate::physics::Model::Full,
            crate::physics::ContactMode::Reciprocal,
        );
        // The fitted curve ends at 600 Hz.
        let fitted_curve = curve(|f| (f <= 600.0).then_some(500.0));
        let rec = SegmentExport::new(segment, Some(fit), fitted_curve);
        assert_eq!(rec.leak_band_speed, None);
        let prediction = db::field::PredictionRow {
            segment_id: "P-1".into(),
            leak_band_speed: Some((494.0, 25.0)),
            note: "from 12 measured segments".into(),
            ..Default::default()
        };
        let rec = rec.set_field(None, Some((prediction, curve(|_| Some(494.0)))));
        assert_eq!(rec.speed_source, SPEED_PREDICTED);
        assert_eq!(rec.leak_band_speed, Some(494.0));
        assert_eq!(rec.leak_band_speed_std(), Some(25.0));
        assert!(
            rec.speed_source_reason
                .starts_with("its fit gives no leak-band speed"),
            "{}",
            rec.speed_source_reason
        );
    }

    #[test]
    fn band_mean_is_exact_for_a_linear_speed() {
        // The trapezoidal rule integrates a linear function exactly: mean of 1000 + 0.2 f over
        // 100..800 Hz is 1000 + 0.2 * 450 = 1090.
        let c = curve(|f| Some(1000.0 + 0.2 * f));
        let m = band_mean_speed(&c, LEAK_BAND_HZ).unwrap();
        assert!((m - 1090.0).abs() < 1e-9, "{m}");
        // A constant curve has that constant as mean.
        let c = curve(|_| Some(1234.5));
        assert!((band_mean_speed(&c, LEAK_BAND_HZ).unwrap() - 1234.5).abs() < 1e-9);
    }

    #[test]
    fn band_mean_weights_by_frequency_spacing() {
        // Speed 2000 only on 800..900 (outside the band) and 1000 inside: the mean stays 1000.
        let c = curve(|f| Some(if f > 800.0 { 2000.0 } else { 1000.0 }));
        assert!((band_mean_speed(&c, LEAK_BAND_HZ).unwrap() - 1000.0).abs() < 1e-9);
        // A step at 450 Hz: the trapezoid spreads it over 450..500 (half weight), so the mean is
        // (1000*350 + 1500*50 + ... ) / 700; compute it independently.
        let c = curve(|f| Some(if f >= 500.0 { 2000.0 } else { 1000.0 }));
        let expected = (1000.0 * (450.0 - 100.0) + 1500.0 * 50.0 + 2000.0 * 300.0) / 700.0;
        assert!((band_mean_speed(&c, LEAK_BAND_HZ).unwrap() - expected).abs() < 1e-9);
    }

    #[test]
    fn band_mean_needs_the_whole_band_and_every_root() {
        let c = curve(|f| if f == 300.0 { None } else { Some(1000.0) });
        assert_eq!(band_mean_speed(&c, LEAK_BAND_HZ), None);
        let c = curve(|f| Some(if f == 300.0 { f64::NAN } else { 1000.0 }));
        assert_eq!(band_mean_speed(&c, LEAK_BAND_HZ), None);
        let part: Vec<CurvePoint> = curve(|_| Some(1000.0))
            .into_iter()
            .filter(|p| p.frequency_hz >= 200.0)
            .collect();
        assert_eq!(band_mean_speed(&part, LEAK_BAND_HZ), None);
        assert_eq!(band_mean_speed(&[], LEAK_BAND_HZ), None);
        // Outside the band a failed root does not matter.
        let c = curve(|f| if f == 2000.0 { None } else { Some(1000.0) });
        assert!(band_mean_speed(&c, LEAK_BAND_HZ).is_some());
    }

    #[test]
    fn export_frequencies_are_on_the_standard_grid() {
        for f in EXPORT_FREQUENCIES_HZ {
            assert!(STANDARD_GRID_HZ.contains(&f), "{f}");
        }
        assert!(STANDARD_GRID_HZ.contains(&LEAK_BAND_HZ.0));
        assert!(STANDARD_GRID_HZ.contains(&LEAK_BAND_HZ.1));
    }

    #[test]
    fn property_names_are_unique_and_segment_id_first() {
        assert_eq!(PROPERTIES[0].name, "segment_id");
        let mut names: Vec<&str> = PROPERTIES.iter().map(|p| p.name).collect();
        names.sort_unstable();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n);
        for p in PROPERTIES {
            assert!(p
                .name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'));
        }
    }
}
