//! The per-segment record of the exports and the audit report, assembled in one place: the
//! inventory row, its latest fit (view `latest_fits`), that fit's curve (same run), the speeds
//! and attenuations at the standard frequencies and the leak-band mean speed. [`Records`] reads
//! them from the database a page at a time, for the writers to stream.
//!
//! [`PROPERTIES`] lists the exported properties, in order, with their types: the GeoPackage
//! columns, the GeoJSON properties and the CSV columns are all made from it, so the three
//! formats cannot drift apart.

use crate::db::wkt::LineString;
use crate::db::{self, pages, CurvePoint, Database, FitRow, SegmentRecord};
use crate::physics::curves::{band_mean, LEAK_BAND_HZ};

use super::ExportError;
use crate::db::crs;

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

/// The SQL/JSON type of a property.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Text.
    Text,
    /// 64-bit float.
    Real,
    /// 64-bit integer.
    Integer,
}

impl Kind {
    /// The GeoPackage column type (OGC 12-128r18 Table 1).
    pub fn gpkg_type(self) -> &'static str {
        match self {
            Kind::Text => "TEXT",
            Kind::Real => "DOUBLE",
            Kind::Integer => "INTEGER",
        }
    }
}

/// The value of one property of one segment.
#[derive(Debug, Clone, PartialEq)]
pub enum Value<'a> {
    /// Missing (NULL, JSON null, empty CSV cell).
    Null,
    /// Text.
    Text(&'a str),
    /// A finite float.
    Real(f64),
    /// An integer.
    Integer(i64),
}

impl Value<'_> {
    fn real(v: Option<f64>) -> Self {
        match v {
            Some(x) if x.is_finite() => Value::Real(x),
            _ => Value::Null,
        }
    }
    fn int(v: Option<i64>) -> Self {
        v.map_or(Value::Null, Value::Integer)
    }
    fn text(v: Option<&str>) -> Value<'_> {
        v.map_or(Value::Null, Value::Text)
    }
}

/// One exported property: its name (GeoPackage column, GeoJSON property, CSV header), type,
/// meaning and how to read it from a record.
pub struct Property {
    /// Name, as in the outputs.
    pub name: &'static str,
    /// Type.
    pub kind: Kind,
    /// Meaning and unit.
    pub doc: &'static str,
    /// The value for a segment.
    pub get: for<'a> fn(&'a SegmentExport) -> Value<'a>,
}

impl std::fmt::Debug for Property {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Property")
            .field("name", &self.name)
            .field("kind", &self.kind)
            .finish()
    }
}

fn zone_real(r: &SegmentExport, get: fn(&db::zones::ZoneFitRow) -> Option<f64>) -> Value<'_> {
    Value::real(r.zone.as_ref().and_then(|z| get(&z.0)))
}

macro_rules! zone_real {
    ($name:literal, $field:ident, $doc:literal) => {
        Property {
            name: $name,
            kind: Kind::Real,
            doc: $doc,
            get: |r| zone_real(r, |z| z.$field),
        }
    };
}

fn fit_real(r: &SegmentExport, get: fn(&FitRow) -> Option<f64>) -> Value<'_> {
    Value::real(r.fit.as_ref().and_then(get))
}

macro_rules! fit_real {
    ($name:literal, $field:ident, $doc:literal) => {
        Property {
            name: $name,
            kind: Kind::Real,
            doc: $doc,
            get: |r| fit_real(r, |f| f.$field),
        }
    };
}

/// The exported properties, in output order; `segment_id` first (the join key).
pub const PROPERTIES: &[Property] = &[
    Property {
        name: "segment_id",
        kind: Kind::Text,
        doc: "the utility's asset id (join key)",
        get: |r| Value::Text(&r.segment.segment_id),
    },
    Property {
        name: "material",
        kind: Kind::Text,
        doc: "pipe material code (CI, DI, ST, PVC, MDPE, HDPE, AC)",
        get: |r| Value::Text(r.segment.material.code()),
    },
    Property {
        name: "outer_diameter_mm",
        kind: Kind::Real,
        doc: "outside diameter, mm",
        get: |r| Value::real(Some(r.segment.outer_diameter_mm)),
    },
    Property {
        name: "wall_thickness_mm",
        kind: Kind::Real,
        doc: "wall thickness, mm",
        get: |r| Value::real(Some(r.segment.wall_thickness_mm)),
    },
    Property {
        name: "soil_type",
        kind: Kind::Text,
        doc: "soil description from the inventory",
        get: |r| Value::text(r.segment.soil_type.as_deref()),
    },
    Property {
        name: "status",
        kind: Kind::Text,
        doc: "latest fit: ok, flagged, failed; unfitted when never fitted",
        get: |r| Value::Text(r.status()),
    },
    Property {
        name: "flags",
        kind: Kind::Text,
        doc: "comma-separated flag codes of the latest fit, and zone_outlier when its soil zone \
              left it out",
        get: |r| Value::text(r.flags.as_deref()),
    },
    Property {
        name: "flag_reasons",
        kind: Kind::Text,
        doc: "what to act on and why, one reason per flag, joined with '; '",
        get: |r| Value::text(r.flag_reasons.as_deref()),
    },
    Property {
        name: "notes",
        kind: Kind::Text,
        doc: "comma-separated note codes: what the data leave undetermined",
        get: |r| Value::text(r.fit.as_ref().map(|f| f.notes.as_str())),
    },
    Property {
        name: "note_reasons",
        kind: Kind::Text,
        doc: "one reason per note, joined with '; ', e.g. E_m and nu_m known only through c_P \
              = 212 +- 9 m/s",
        get: |r| Value::text(r.fit.as_ref().map(|f| f.note_reasons.as_str())),
    },
    Property {
        name: "run_id",
        kind: Kind::Integer,
        doc: "the calibrate run of the latest fit",
        get: |r| Value::int(r.fit.as_ref().map(|f| f.run_id)),
    },
    Property {
        name: "model",
        kind: Kind::Text,
        doc: "model variant of the fit (full, seed)",
        get: |r| Value::text(r.fit.as_ref().map(|f| f.model.as_str())),
    },
    Property {
        name: "effects",
        kind: Kind::Text,
        doc: "comma-separated effects switched on for the fit",
        get: |r| Value::text(r.fit.as_ref().map(|f| f.effects.as_str())),
    },
    fit_real!(
        "soil_youngs_modulus_pa",
        soil_youngs_modulus_pa,
        "fitted soil Young's modulus E, Pa"
    ),
    fit_real!(
        "soil_youngs_modulus_std_pa",
        soil_youngs_modulus_std_pa,
        "its one-sigma error, Pa"
    ),
    fit_real!(
        "soil_poisson",
        soil_poisson,
        "fitted soil Poisson's ratio nu"
    ),
    fit_real!("soil_poisson_std", soil_poisson_std, "its one-sigma error"),
    fit_real!(
        "contact",
        contact,
        "fitted pipe-soil contact coefficient xi"
    ),
    fit_real!("contact_std", contact_std, "its one-sigma error"),
    fit_real!(
        "soil_p_wave_speed_m_per_s",
        soil_p_wave_speed_m_per_s,
        "the soil's compressional speed c_P, m/s (what metal pipes determine)"
    ),
    fit_real!(
        "soil_p_wave_speed_std_m_per_s",
        soil_p_wave_speed_std_m_per_s,
        "its one-sigma error, m/s"
    ),
    fit_real!(
        "soil_s_wave_speed_m_per_s",
        soil_s_wave_speed_m_per_s,
        "the soil's shear speed c_S, m/s (what plastic pipes also determine)"
    ),
    fit_real!(
        "soil_s_wave_speed_std_m_per_s",
        soil_s_wave_speed_std_m_per_s,
        "its one-sigma error, m/s"
    ),
    fit_real!(
        "soil_youngs_modulus_lo_pa",
        soil_youngs_modulus_lo_pa,
        "95 % interval of E, lower end, Pa"
    ),
    fit_real!(
        "soil_youngs_modulus_hi_pa",
        soil_youngs_modulus_hi_pa,
        "95 % interval of E, upper end, Pa"
    ),
    fit_real!(
        "soil_poisson_lo",
        soil_poisson_lo,
        "95 % interval of nu, lower end"
    ),
    fit_real!(
        "soil_poisson_hi",
        soil_poisson_hi,
        "95 % interval of nu, upper end"
    ),
    fit_real!("contact_lo", contact_lo, "95 % interval of xi, lower end"),
    fit_real!("contact_hi", contact_hi, "95 % interval of xi, upper end"),
    fit_real!(
        "soil_loss_factor",
        soil_loss_factor,
        "soil loss factor (effect soil_damping)"
    ),
    fit_real!(
        "soil_loss_factor_std",
        soil_loss_factor_std,
        "its one-sigma error"
    ),
    fit_real!(
        "air_fraction",
        air_fraction,
        "air volume fraction (effect air_in_water)"
    ),
    fit_real!("air_fraction_std", air_fraction_std, "its one-sigma error"),
    fit_real!(
        "wall_thickness_ratio",
        wall_thickness_ratio,
        "effective/nominal wall (effect wall_thinning)"
    ),
    fit_real!(
        "wall_thickness_ratio_std",
        wall_thickness_ratio_std,
        "its one-sigma error"
    ),
    fit_real!(
        "pipe_loss_factor",
        pipe_loss_factor,
        "fitted pipe loss factor (effect pipe_loss)"
    ),
    fit_real!(
        "pipe_loss_factor_std",
        pipe_loss_factor_std,
        "its one-sigma error"
    ),
    fit_real!("misfit", misfit, "objective value at the optimum"),
    fit_real!(
        "chi2_per_dof",
        chi2_per_dof,
        "chi-squared per degree of freedom"
    ),
    Property {
        name: "n_measurements",
        kind: Kind::Integer,
        doc: "measurements used by the fit",
        get: |r| Value::int(r.fit.as_ref().and_then(|f| f.n_measurements)),
    },
    Property {
        name: "speed_100hz_m_per_s",
        kind: Kind::Real,
        doc: "phase speed at 100 Hz, m/s",
        get: |r| Value::real(r.speed_at[0]),
    },
    Property {
        name: "speed_200hz_m_per_s",
        kind: Kind::Real,
        doc: "phase speed at 200 Hz, m/s",
        get: |r| Value::real(r.speed_at[1]),
    },
    Property {
        name: "speed_500hz_m_per_s",
        kind: Kind::Real,
        doc: "phase speed at 500 Hz, m/s",
        get: |r| Value::real(r.speed_at[2]),
    },
    Property {
        name: "speed_1000hz_m_per_s",
        kind: Kind::Real,
        doc: "phase speed at 1000 Hz, m/s",
        get: |r| Value::real(r.speed_at[3]),
    },
    Property {
        name: "attenuation_100hz_db_per_m",
        kind: Kind::Real,
        doc: "attenuation at 100 Hz, dB/m",
        get: |r| Value::real(r.attenuation_at[0]),
    },
    Property {
        name: "attenuation_200hz_db_per_m",
        kind: Kind::Real,
        doc: "attenuation at 200 Hz, dB/m",
        get: |r| Value::real(r.attenuation_at[1]),
    },
    Property {
        name: "attenuation_500hz_db_per_m",
        kind: Kind::Real,
        doc: "attenuation at 500 Hz, dB/m",
        get: |r| Value::real(r.attenuation_at[2]),
    },
    Property {
        name: "attenuation_1000hz_db_per_m",
        kind: Kind::Real,
        doc: "attenuation at 1000 Hz, dB/m",
        get: |r| Value::real(r.attenuation_at[3]),
    },
    Property {
        name: "leak_band_speed_m_per_s",
        kind: Kind::Real,
        doc: "mean phase speed over 100-800 Hz (trapezoidal rule on the stored grid), m/s: \
              the figure to type into a leak correlator",
        get: |r| Value::real(r.leak_band_speed),
    },
    Property {
        name: "leak_band_speed_std_m_per_s",
        kind: Kind::Real,
        doc: "one-sigma error of the leak-band speed, m/s (the fit's, physics P65, or the \
              prediction's, P81)",
        get: |r| Value::real(r.leak_band_speed_std()),
    },
    Property {
        name: "curve_source",
        kind: Kind::Text,
        doc: "model, or model+discrepancy where the model does not explain the data and the \
              speeds and their errors include a discrepancy fitted to the residuals (physics \
              §7.13)",
        get: |r| Value::text(r.fit.as_ref().map(|f| f.curve_source.as_str())),
    },
    fit_real!(
        "leak_band_extrapolation_octaves",
        leak_band_extrapolation_octaves,
        "how far the leak band 100-800 Hz reaches beyond the measured frequencies, octaves"
    ),
    Property {
        name: "soil_zone",
        kind: Kind::Text,
        doc: "the soil unit of the inventory (model §7.11)",
        get: |r| Value::text(r.segment.soil_zone.as_deref()),
    },
    zone_real!(
        "zone_soil_youngs_modulus_pa",
        soil_youngs_modulus_pa,
        "the zone's E_m, Pa (hierarchical estimate, physics P67-P68)"
    ),
    zone_real!(
        "zone_soil_youngs_modulus_lo_pa",
        soil_youngs_modulus_lo_pa,
        "95 % interval of the zone's E_m: lower end, Pa"
    ),
    zone_real!(
        "zone_soil_youngs_modulus_hi_pa",
        soil_youngs_modulus_hi_pa,
        "95 % interval of the zone's E_m: upper end, Pa"
    ),
    zone_real!("zone_soil_poisson", soil_poisson, "the zone's nu_m"),
    zone_real!(
        "zone_soil_poisson_lo",
        soil_poisson_lo,
        "95 % interval of the zone's nu_m: lower end"
    ),
    zone_real!(
        "zone_soil_poisson_hi",
        soil_poisson_hi,
        "95 % interval of the zone's nu_m: upper end"
    ),
    zone_real!(
        "zone_soil_p_wave_speed_m_per_s",
        soil_p_wave_speed_m_per_s,
        "the zone's compressional speed c_P at its mean soil density, m/s (P63)"
    ),
    zone_real!(
        "zone_soil_s_wave_speed_m_per_s",
        soil_s_wave_speed_m_per_s,
        "the zone's shear speed c_S at its mean soil density, m/s (P64)"
    ),
    Property {
        name: "zone_shrunk_soil_youngs_modulus_pa",
        kind: Kind::Real,
        doc: "this segment's E_m shrunk toward its zone, Pa (P68)",
        get: |r| {
            Value::real(
                r.zone
                    .as_ref()
                    .and_then(|z| z.1.shrunk_soil_youngs_modulus_pa),
            )
        },
    },
    Property {
        name: "zone_shrunk_soil_poisson",
        kind: Kind::Real,
        doc: "this segment's nu_m shrunk toward its zone (P68)",
        get: |r| Value::real(r.zone.as_ref().and_then(|z| z.1.shrunk_soil_poisson)),
    },
    Property {
        name: "zone_outlier",
        kind: Kind::Integer,
        doc: "1 if this segment disagrees with its zone and was left out of its estimate",
        get: |r| Value::int(r.zone.as_ref().map(|z| i64::from(z.1.zone_outlier))),
    },
    Property {
        name: "zone_statistic",
        kind: Kind::Real,
        doc: "this segment's misfit at its zone with the scatter allowed for (chi-square, 2 \
              dof); above 13.82 (p < 0.001) it is a zone_outlier",
        get: |r| Value::real(r.zone.as_ref().and_then(|z| z.1.statistic)),
    },
    Property {
        name: "speed_source",
        kind: Kind::Text,
        doc: "where the speed comes from: fitted (its own measurements), predicted (the soil \
              field of the network, physics P81) or none",
        get: |r| Value::Text(r.speed_source),
    },
    Property {
        name: "speed_source_reason",
        kind: Kind::Text,
        doc: "what the speed rests on, or why there is none",
        get: |r| Value::Text(&r.speed_source_reason),
    },
    Property {
        name: "soil_class",
        kind: Kind::Text,
        doc: "the soil class the field used (soil_zone, else soil_type; the neighbourhood's \
              majority where it rejects the label)",
        get: |r| Value::text(r.field.as_ref().and_then(|f| f.soil_class.as_deref())),
    },
    Property {
        name: "label_rejected",
        kind: Kind::Integer,
        doc: "1 if most of the segment's nearest neighbours carry another soil label",
        get: |r| Value::int(r.field.as_ref().map(|f| i64::from(f.label_rejected))),
    },
    Property {
        name: "field_leak_band_speed_m_per_s",
        kind: Kind::Real,
        doc: "the soil field's leak-band speed: for a measured segment predicted from the \
              others (leave-one-out, P82), for comparison with its own fit, m/s",
        get: |r| {
            Value::real(
                r.field
                    .as_ref()
                    .and_then(|f| f.field_leak_band_speed_m_per_s)
                    .or_else(|| {
                        r.prediction
                            .as_ref()
                            .and_then(|p| p.leak_band_speed.map(|v| v.0))
                    }),
            )
        },
    },
    Property {
        name: "field_leak_band_speed_std_m_per_s",
        kind: Kind::Real,
        doc: "its one-sigma error, m/s",
        get: |r| {
            Value::real(
                r.field
                    .as_ref()
                    .and_then(|f| f.field_leak_band_speed_std_m_per_s)
                    .or_else(|| {
                        r.prediction
                            .as_ref()
                            .and_then(|p| p.leak_band_speed.map(|v| v.1))
                    }),
            )
        },
    },
    Property {
        name: "field_z",
        kind: Kind::Real,
        doc: "leave-one-out z of a measured segment (P82): its fit against its neighbours' \
              prediction, in combined sigmas",
        get: |r| Value::real(r.field.as_ref().and_then(|f| f.loo_z)),
    },
    Property {
        name: "field_outlier",
        kind: Kind::Integer,
        doc: "1 if |field_z| exceeds 3.29 (p < 0.001): a wrong record, a changed soil or a leak",
        get: |r| Value::int(r.field.as_ref().map(|f| i64::from(f.field_outlier))),
    },
    Property {
        name: "soil_class_override",
        kind: Kind::Text,
        doc: "the soil class the inventory forces for this segment (the field uses it without \
              the neighbourhood test that may reject a label), as given",
        get: |r| Value::text(r.segment.soil_class_override.as_deref()),
    },
    Property {
        name: "class_overridden",
        kind: Kind::Integer,
        doc: "1 if the field's last update took soil_class from soil_class_override",
        get: |r| Value::int(r.field.as_ref().map(|f| i64::from(f.class_overridden))),
    },
    Property {
        name: "risk_weight",
        kind: Kind::Real,
        doc: "the inventory's weight of this segment's speed error in plan (P83); blank: its \
              length is used",
        get: |r| Value::real(r.segment.risk_weight),
    },
    Property {
        name: "change_status",
        kind: Kind::Text,
        doc: "the change test of the latest campaign against the one before it (model §7.14): \
              changed, unchanged (both campaigns pooled into the fit), one_campaign, or \
              untested (no standard deviations, a failed fit); blank: not fitted since \
              campaigns were tested",
        get: |r| Value::text(r.change.as_ref().map(|c| c.status.as_str())),
    },
    Property {
        name: "change_since",
        kind: Kind::Text,
        doc: "the earlier campaign the latest was tested against",
        get: |r| Value::text(r.change.as_ref().and_then(|c| c.since_campaign.as_deref())),
    },
    Property {
        name: "change_p_value",
        kind: Kind::Real,
        doc: "the change test's p-value (P94): the chance of so large a difference between \
              the campaigns if the pipe had not changed; changed below 0.005",
        get: |r| Value::real(r.change.as_ref().and_then(|c| c.p_value)),
    },
    Property {
        name: "change_leak_band_speed_pct",
        kind: Kind::Real,
        doc: "the leak-band speed of the latest campaign against the earlier one, each fitted \
              on its own, %",
        get: |r| Value::real(r.change.as_ref().and_then(|c| c.leak_band_speed_pct)),
    },
    Property {
        name: "change_leak_band_speed_pct_std",
        kind: Kind::Real,
        doc: "its one-sigma error, %",
        get: |r| Value::real(r.change.as_ref().and_then(|c| c.leak_band_speed_pct_std)),
    },
    Property {
        name: "change_effect",
        kind: Kind::Text,
        doc: "what changed, where the pipe changed (P95): soil_change, air_in_water, \
              wall_thinning, pipe_loss, or unexplained",
        get: |r| Value::text(r.change.as_ref().and_then(|c| c.effect.as_deref())),
    },
    Property {
        name: "change_ambiguous_with",
        kind: Kind::Text,
        doc: "causes the data cannot tell apart from change_effect (AICc within 2), \
              `; `-separated",
        get: |r| {
            Value::text(
                r.change
                    .as_ref()
                    .filter(|c| !c.ambiguous_with.is_empty())
                    .map(|c| c.ambiguous_with.as_str()),
            )
        },
    },
    Property {
        name: "change_note",
        kind: Kind::Text,
        doc: "what the change test leaves open, or why it did not run",
        get: |r| Value::text(r.change.as_ref().and_then(|c| c.note.as_deref())),
    },
    Property {
        name: "speed_by_campaign",
        kind: Kind::Text,
        doc: "each campaign's leak-band speed fitted on its own, oldest first: \
              `CAMPAIGN: SPEED ± STD m/s` joined by `; `",
        get: |r| Value::text(r.speed_by_campaign.as_deref()),
    },
];

/// [`SegmentExport::speed_history`] as one line: `CAMPAIGN: SPEED ± STD m/s; …`, each speed
/// printed to the place of its error (`None` when there is none).
pub fn speed_by_campaign(history: &[db::changes::CampaignSpeedRow]) -> Option<String> {
    let parts: Vec<String> = history
        .iter()
        .filter_map(|h| {
            let v = h.leak_band_speed_m_per_s?;
            Some(match h.leak_band_speed_std_m_per_s.filter(|e| *e > 0.0) {
                Some(e) => {
                    let place = super::numbers::error_place(e);
                    format!(
                        "{}: {} ± {} m/s",
                        h.campaign,
                        super::numbers::fixed(v, place),
                        super::numbers::fixed(e, place)
                    )
                }
                None => format!("{}: {v:.0} m/s", h.campaign),
            })
        })
        .collect();
    (!parts.is_empty()).then(|| parts.join("; "))
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
