//! The soil field over the network (model §7.12): every segment gets a speed.
//!
//! The fitted segments observe the soil u = (ln c_P, ln c_S) through their information (P79);
//! [`model`] pools them into a Gaussian field with class means and a spatially correlated part
//! (P78, P80); [`labels`] decides each segment's class from its label and its neighbours';
//! [`predict`] carries the field's posterior through the forward model to a speed (P81);
//! [`update_field`] does it all after a calibrate run: predictions for every segment without a
//! fitted speed, the leave-one-out check of every measured one (P82), stored in place of the
//! previous update's. [`plan`] chooses where to measure next (P83).

pub mod joint;
pub mod labels;
pub mod model;
pub mod plan;
pub mod predict;

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::time::Instant;

use rayon::prelude::*;
use rusqlite::Connection;

use crate::db::field::{
    self as store, FieldClassRow, FieldInput, FieldRunRow, FieldSegmentRow, Prediction,
    PredictionRow,
};
use crate::db::hash::{fnv1a64, fnv1a64_update, FNV1A64_START};
use crate::db::wkt::LineString;
use crate::db::{pages, DbError, SegmentRecord};
use crate::invert::uncertainty::soil_intervals_of_speeds;
use crate::physics::curves::LEAK_BAND_HZ;
use crate::physics::soil::soil_speeds;
use crate::physics::{ContactMode, Model};

use model::{ClassMean, Field, Observation, Posterior, Screened, Sym2, NEIGHBOURS};
use predict::{predict_speed, soil_of, SpeedPrediction};

/// Version of the field's method, part of its fingerprint: a new version rebuilds the field.
pub const FIELD_ALGORITHM_VERSION: u32 = 10;

/// |z| of the leave-one-out check (P82) beyond which a measured segment is flagged
/// `field_outlier`: the two-sided 0.1 % point of N(0, 1), so that a network of a thousand
/// measured segments that the field describes well gets about one false alarm.
pub const FIELD_OUTLIER_Z: f64 = 3.29;

/// The one class of a network whose inventory has neither `soil_zone` nor `soil_type`.
pub const NETWORK_CLASS: &str = "network";

/// The class of segments without a label whose neighbourhood has none either.
pub const UNLABELLED_CLASS: &str = "unlabelled";

/// A class less probable than this for a segment is left out of its mixture (model §7.12:
/// labels are evidence; its share of the prediction would be below 1 %).
pub const MIN_CLASS_PROBABILITY: f64 = 0.01;

/// Segments read from the inventory at a time for the predictions (flat memory).
const PAGE: usize = 256;

/// Mean Earth radius, m (IUGG), for distances between longitude/latitude midpoints.
const EARTH_RADIUS_M: f64 = 6_371_008.8;

/// A neighbour further than this many correlation lengths away hardly informs a prediction
/// (weight e⁻² or less); the note counts only the nearer ones.
const INFORMATIVE_LENGTHS: f64 = 2.0;

/// How the field is updated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldSettings {
    /// The model variant the speeds are computed with (the run's).
    pub model: Model,
    /// The contact reading (the run's).
    pub contact_mode: ContactMode,
    /// Worker threads (the result does not depend on it).
    pub jobs: usize,
    /// Rebuild even when the inputs are unchanged.
    pub force: bool,
}

/// What a field update did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FieldUpdate {
    /// The stored field and predictions were current: nothing was done.
    pub up_to_date: bool,
    /// The field run's row (the stored one when up to date).
    pub run: FieldRunRow,
    /// The declared soil zones: estimated as the zone classes' means when the field is
    /// rebuilt, all up to date when it is current (None when the inventory declares no zone).
    pub zones: Option<crate::zones::ZoneUpdate>,
}

impl FieldUpdate {
    /// The summary line, e.g. `field: 81 segments predicted from 21 measured (3 classes,
    /// correlation length 350 m); leave-one-out z spread 1.04, 0 field outliers; 2 labels
    /// rejected; in 1.2 s`.
    pub fn line(&self) -> String {
        let r = &self.run;
        if self.up_to_date {
            return format!(
                "field: up to date ({} segments predicted from {} measured)",
                r.n_predicted, r.n_measured
            );
        }
        let mut s = format!(
            "field: {} segments predicted from {} measured ({} class{}",
            r.n_predicted,
            r.n_measured,
            r.n_classes,
            if r.n_classes == 1 { "" } else { "es" }
        );
        if let Some(l) = r.correlation_length_m {
            let _ = write!(s, ", correlation length {l:.0} m");
        }
        if r.hyper_source == model::HyperSource::Defaults.as_str() && r.n_measured > 0 {
            s.push_str(", default hyper-parameters: too few measured");
        }
        s.push(')');
        if let Some(z) = r.loo_z_std {
            let _ = write!(s, "; leave-one-out z spread {z:.2}");
        }
        let _ = write!(
            s,
            ", {} field outlier{}; {} label{} rejected",
            r.n_field_outliers,
            if r.n_field_outliers == 1 { "" } else { "s" },
            r.n_labels_rejected,
            if r.n_labels_rejected == 1 { "" } else { "s" }
        );
        if r.n_without_speed > 0 {
            let _ = write!(s, "; {} without a speed", r.n_without_speed);
        }
        if let Some(t) = r.elapsed_s {
            let _ = write!(s, "; in {t:.1} s");
        }
        s
    }
}

/// One segment as the field sees it.
#[derive(Debug, Clone)]
pub struct Site {
    /// The segment.
    pub segment_id: String,
    /// Its midpoint in metres (None: no readable geometry).
    pub pos: Option<[f64; 2]>,
    /// Its length, m (geometry, else the inventory's `length_m`).
    pub length: Option<f64>,
    /// Its material code.
    pub material: String,
    /// Its label as given (`soil_zone`, else `soil_type`).
    pub label: Option<String>,
    /// Its class index.
    pub class: Option<usize>,
    /// Its neighbourhood rejects its label.
    pub label_rejected: bool,
    /// The inventory's `soil_class_override`: the class the engineer has checked, used as it
    /// is (no neighbourhood test, no class uncertainty).
    pub class_override: Option<String>,
    /// Its weight in `plan` (P83): the inventory's `risk_weight` where given, else its length.
    pub risk_weight: Option<f64>,
    /// The probabilities of its true class (labels are evidence): its class alone when its
    /// neighbourhood agrees.
    pub classes: Vec<(usize, f64)>,
    /// Its index among the field's members, when it has a usable fit.
    pub member: Option<usize>,
    /// Its fitted leak-band speed and error, m/s.
    pub fitted_speed: Option<(f64, f64)>,
    /// Its soil density from the inventory, kg/m³.
    pub soil_density: Option<f64>,
}

/// Midpoint (along its length) and length of a polyline, in the units of its coordinates.
fn midpoint_and_length(points: &[(f64, f64)]) -> Option<([f64; 2], f64)> {
    let seg = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0).hypot(b.1 - a.1);
    let total: f64 = points.windows(2).map(|w| seg(w[0], w[1])).sum();
    if !total.is_finite() || points.is_empty() {
        return None;
    }
    let mut left = 0.5 * total;
    for w in points.windows(2) {
        let d = seg(w[0], w[1]);
        if d >= left && d > 0.0 {
            let t = left / d;
            return Some((
                [
                    w[0].0 + t * (w[1].0 - w[0].0),
                    w[0].1 + t * (w[1].1 - w[0].1),
                ],
                total,
            ));
        }
        left -= d;
    }
    Some(([points[0].0, points[0].1], total))
}

/// A segment's midpoint and length in metres: projected coordinates as they are, longitude and
/// latitude by a local equirectangular projection (adequate over a network's extent).
fn site_geometry(wkt: Option<&str>, srid: Option<i64>) -> Option<([f64; 2], f64)> {
    let line = LineString::parse_wkt(wkt?).ok()?;
    let geographic = srid.is_some_and(crate::db::crs::is_geographic);
    if !geographic {
        return midpoint_and_length(&line.points);
    }
    let lat0 = line.points.iter().map(|p| p.1).sum::<f64>() / line.points.len() as f64;
    let k = EARTH_RADIUS_M * std::f64::consts::PI / 180.0;
    let pts: Vec<(f64, f64)> = line
        .points
        .iter()
        .map(|p| (p.0 * k * lat0.to_radians().cos(), p.1 * k))
        .collect();
    midpoint_and_length(&pts)
}

/// A label: the text, trimmed, when it holds more than spaces.
fn label_of(v: Option<&str>) -> Option<String> {
    v.map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_string)
}

/// The fingerprint of everything a field update depends on, hashed as the inputs stream past
/// (FNV-1a is a fold over the bytes, so the value is that of the whole text).
struct Fingerprint(u64);

impl Fingerprint {
    fn new(settings: &FieldSettings) -> Fingerprint {
        let head = format!(
            "field v{FIELD_ALGORITHM_VERSION} {} {}\n",
            settings.model.as_str(),
            settings.contact_mode.as_str()
        );
        Fingerprint(fnv1a64_update(FNV1A64_START, head.as_bytes()))
    }

    fn add(&mut self, i: &FieldInput) {
        let line = format!(
            "{}|{}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}\n",
            i.segment_id,
            i.inputs_hash,
            i.soil_type,
            i.soil_zone,
            i.geometry_wkt,
            i.srid,
            i.length_m,
            i.fit_id
        );
        self.0 = fnv1a64_update(self.0, line.as_bytes());
        // The override changes the segment's class; appended only where given, so a network
        // without overrides keeps the fingerprint it had before the column existed.
        if let Some(o) = &i.soil_class_override {
            self.0 = fnv1a64_update(self.0, format!("override {o:?}\n").as_bytes());
        }
    }

    fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// What a segment's input gives the field besides its site: its fit's soil, if usable.
#[derive(Debug, Clone, Copy)]
struct FittedSoil {
    speeds: Option<(f64, f64)>,
    information: Option<[f64; 3]>,
    usable: bool,
    suspect: bool,
}

/// Whether a fit's own findings say its information may mislead the field
/// ([`Observation::suspect`]): `near_grazing`, or `soil_undetermined` on a metal pipe.
fn suspect_fit(material: &str, findings: &str) -> bool {
    use crate::invert::flags::FlagCode;
    let has = |code: FlagCode| findings.split(',').any(|c| c.trim() == code.as_str());
    let metal = material
        .parse::<crate::physics::Material>()
        .is_ok_and(|m| !m.is_plastic());
    has(FlagCode::NearGrazing) || (metal && has(FlagCode::SoilUndetermined))
}

/// A segment's site (its geometry reduced to a midpoint and a length) and its fit's soil.
fn site_of(i: &FieldInput) -> (Site, FittedSoil) {
    let geo = site_geometry(i.geometry_wkt.as_deref(), i.srid);
    let usable = matches!(i.fit_status.as_deref(), Some("ok" | "flagged"));
    (
        Site {
            segment_id: i.segment_id.clone(),
            pos: geo.map(|g| g.0),
            length: geo.map(|g| g.1).or(i.length_m),
            material: i.material.clone(),
            label: label_of(i.soil_zone.as_deref()).or_else(|| label_of(i.soil_type.as_deref())),
            class: None,
            label_rejected: false,
            class_override: label_of(i.soil_class_override.as_deref()),
            risk_weight: i.risk_weight,
            classes: Vec::new(),
            member: None,
            fitted_speed: i.leak_band_speed.filter(|_| usable),
            soil_density: i.soil_density,
        },
        FittedSoil {
            speeds: i.speeds,
            information: i.information,
            usable,
            suspect: suspect_fit(&i.material, &i.fit_findings),
        },
    )
}

/// The sites, the field's members and the class names.
type SitesAndMembers = (Vec<Site>, Vec<Observation>, Vec<String>);

/// Read every segment's site from the database, one inventory row at a time (no geometry text
/// is kept: flat memory), with the fingerprint of the inputs; then the classes and members.
/// The sites are read into a list of the inventory's size (a growing list would hold up to
/// twice that, and its copies) and only the fitted segments' soils are kept.
fn read_sites(
    conn: &Connection,
    settings: &FieldSettings,
) -> Result<(String, SitesAndMembers), DbError> {
    let mut fp = Fingerprint::new(settings);
    let (sites, soils) = read_sites_and_soils(conn, |i| fp.add(i))?;
    Ok((fp.hex(), classes_and_members(sites, &soils)))
}

/// The fitted soils of the segments whose fit is usable, with their sites' indices.
type MemberSoils = Vec<(usize, FittedSoil)>;

/// Every segment's site in inventory order, and the fitted soils of those whose fit is usable
/// (in site order); `each` sees every input as it streams past.
fn read_sites_and_soils(
    conn: &Connection,
    mut each: impl FnMut(&FieldInput),
) -> Result<(Vec<Site>, MemberSoils), DbError> {
    let n = store::count_segments(conn)?;
    let mut sites = Vec::with_capacity(usize::try_from(n).unwrap_or(0));
    let mut soils = Vec::new();
    store::for_each_field_input(conn, |i| {
        each(&i);
        let (site, soil) = site_of(&i);
        if soil.usable {
            soils.push((sites.len(), soil));
        }
        sites.push(site);
        Ok(())
    })?;
    Ok((sites, soils))
}

/// The sites and members of the field from the inputs, with the class names.
pub fn sites_of(inputs: &[FieldInput]) -> (Vec<Site>, Vec<Observation>, Vec<String>) {
    let (sites, soils): (Vec<Site>, Vec<FittedSoil>) = inputs.iter().map(site_of).unzip();
    let soils: MemberSoils = soils
        .into_iter()
        .enumerate()
        .filter(|(_, s)| s.usable)
        .collect();
    classes_and_members(sites, &soils)
}

/// Classes (labels smoothed over neighbours, with their probabilities) and the members: the
/// sites with usable fits, `soils` (site index, soil) in site order.
fn classes_and_members(
    mut sites: Vec<Site>,
    soils: &[(usize, FittedSoil)],
) -> (Vec<Site>, Vec<Observation>, Vec<String>) {
    // Classes: the labels and overrides in sorted order (one "network" class when there are
    // none). An override stands for the segment's label in its neighbours' votes too: it is the
    // engineer's corrected label.
    let mut names: Vec<String> = sites
        .iter()
        .filter_map(|s| s.class_override.as_deref().or(s.label.as_deref()))
        .collect::<BTreeSet<&str>>()
        .into_iter()
        .map(str::to_string)
        .collect();
    let index: BTreeMap<&str, usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let own: Vec<Option<usize>> = sites
        .iter()
        .map(|s| {
            s.class_override
                .as_deref()
                .or(s.label.as_deref())
                .map(|l| index[l])
        })
        .collect();
    let pos: Vec<Option<[f64; 2]>> = sites.iter().map(|s| s.pos).collect();
    // Each segment's class probabilities from its label and its neighbours' (labels are
    // evidence, model §7.12), under the network's own label error rate; an override is the
    // engineer's checked class, certain.
    let forced: Vec<bool> = sites.iter().map(|s| s.class_override.is_some()).collect();
    let (beliefs, _) = labels::classes(&own, &forced, &pos, names.len(), MIN_CLASS_PROBABILITY);
    let fallback = if names.is_empty() {
        NETWORK_CLASS
    } else {
        UNLABELLED_CLASS
    };
    let mut fallback_index = None;
    for (s, b) in sites.iter_mut().zip(beliefs) {
        let class = b.class.unwrap_or_else(|| {
            *fallback_index.get_or_insert_with(|| {
                names.push(fallback.to_string());
                names.len() - 1
            })
        });
        s.class = Some(class);
        s.label_rejected = b.rejected;
        s.classes = if b.probabilities.is_empty() {
            vec![(class, 1.0)]
        } else {
            b.probabilities
        };
    }
    let mut obs = Vec::new();
    for &(at, i) in soils {
        let s = &mut sites[at];
        let (Some((cp, cs)), Some(info), true) = (i.speeds, i.information, i.usable) else {
            continue;
        };
        if !(cp > 0.0 && cs > 0.0 && info.iter().all(|v| v.is_finite())) {
            continue;
        }
        s.member = Some(obs.len());
        obs.push(Observation {
            pos: s.pos,
            class: s.class.unwrap_or(0),
            u: [cp.ln(), cs.ln()],
            info: Sym2::new(info[0], info[1], info[2]),
            key: fnv1a64(s.segment_id.as_bytes()),
            suspect: i.suspect,
        });
    }
    (sites, obs, names)
}

/// The given class means (model §7.12): a class named after a declared soil zone with an
/// estimate takes the zone's soil from the hierarchical model of its members (§7.11, P67–P68)
/// as its mean, with the zone's posterior covariance; the other classes have none (the field
/// estimates theirs). A zone whose covariance the grid could not give keeps the field's
/// estimate.
pub fn zone_class_means(
    names: &[String],
    zones: &crate::zones::ZoneEstimates,
) -> Vec<Option<ClassMean>> {
    names
        .iter()
        .map(|n| {
            let z = zones.get(n)?;
            let e = &z.estimate;
            let [pp, ps, ss] = e.speed_cov?;
            let (cp, cs) = e.speeds();
            let mean = [cp.ln(), cs.ln()];
            (mean.iter().all(|v| v.is_finite()) && e.soil_density > 0.0).then_some(ClassMean {
                mean,
                cov: Sym2::new(pp, ps, ss),
                density: e.soil_density,
            })
        })
        .collect()
}

/// The members with their fitted u moved to their class's density where the class has a
/// given mean (û + ½ ln(ρ_s/ρ_k), P63–P64 at fixed E_m, ν_m), so that the field's correlated
/// part and scatter act on the residuals about the zone's soil at each pipe's own density.
fn at_class_density(
    mut obs: Vec<Observation>,
    sites: &[Site],
    means: &[Option<ClassMean>],
) -> Vec<Observation> {
    for s in sites {
        let (Some(m), Some(rho)) = (s.member, s.soil_density) else {
            continue;
        };
        let o = &mut obs[m];
        if let Some(g) = means.get(o.class).and_then(Option::as_ref) {
            let d = g.shift(rho);
            o.u = [o.u[0] - d, o.u[1] - d];
        }
    }
    obs
}

/// The bounds of ℓ (model §7.12): a typical segment length (the median) and the network's
/// extent (the diagonal of the midpoints' bounding box), m.
pub fn length_bounds(sites: &[Site]) -> (f64, f64) {
    let mut lengths: Vec<f64> = sites
        .iter()
        .filter_map(|s| s.length)
        .filter(|l| *l > 0.0 && l.is_finite())
        .collect();
    lengths.sort_by(f64::total_cmp);
    let typical = lengths.get(lengths.len() / 2).copied().unwrap_or(100.0);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in sites.iter().filter_map(|s| s.pos) {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let extent = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    let extent = if extent.is_finite() { extent } else { 0.0 };
    (typical, extent.max(10.0 * typical))
}

/// The note of a prediction: what it rests on.
fn note_of(site: &Site, post: &Posterior, field: &Field, class: &str) -> String {
    let reach = INFORMATIVE_LENGTHS * field.hyper.ell;
    let near: Vec<f64> = post
        .neighbours
        .iter()
        .map(|n| n.1)
        .filter(|d| *d <= reach)
        .collect();
    let mut note = if site.pos.is_none() {
        format!("no geometry: the mean of soil class {class}")
    } else if near.is_empty() {
        format!(
            "no measured segment within {:.0} m: the mean of soil class {class}",
            reach
        )
    } else {
        format!(
            "from {} measured segment{} within {:.0} m; soil class {class}",
            near.len(),
            if near.len() == 1 { "" } else { "s" },
            near.iter().copied().fold(0.0, f64::max)
        )
    };
    if site.class_override.is_some() {
        note.push_str(" (class set by soil_class_override)");
    }
    if site.label_rejected {
        let _ = write!(
            note,
            "; its label {} is rejected by its neighbourhood",
            site.label.as_deref().unwrap_or("")
        );
    }
    note
}

/// The stored prediction of a site from its posterior and the quadrature's speed.
fn prediction_row(
    site: &Site,
    run_id: Option<i64>,
    post: &Posterior,
    speed: &SpeedPrediction,
    rho: f64,
    class: &str,
    note: String,
) -> PredictionRow {
    let (cp, cs) = (post.mean[0].exp(), post.mean[1].exp());
    let soil = soil_of(post.mean, rho);
    let intervals = soil.and_then(|(e, nu)| {
        let u = {
            let (p, s) = soil_speeds(e, nu, rho);
            [p.ln(), s.ln()]
        };
        soil_intervals_of_speeds(u, [post.cov.pp, post.cov.ps, post.cov.ps, post.cov.ss], rho)
            .map(|(ie, inu)| ((e, ie.lo, ie.hi), (nu, inu.lo, inu.hi)))
    });
    PredictionRow {
        segment_id: site.segment_id.clone(),
        run_id,
        soil_p_wave_speed: Some((cp, cp * post.cov.pp.max(0.0).sqrt())),
        soil_s_wave_speed: Some((cs, cs * post.cov.ss.max(0.0).sqrt())),
        soil_youngs_modulus: intervals.map(|i| i.0),
        soil_poisson: intervals.map(|i| i.1),
        leak_band_speed: speed.band.map(|b| (b.value, b.std)),
        leak_band_speed_gradient: speed.band_gradient,
        soil_class: Some(class.to_string()),
        n_neighbours: post.neighbours.len() as i64,
        note,
    }
}

/// What the field computes for one site: its prediction (unmeasured) or its leave-one-out row
/// (measured), and the speed's gradient in u (for `plan`).
struct SiteResult {
    row: FieldSegmentRow,
    prediction: Option<Prediction>,
}

/// The field's work on one site.
fn site_result(
    site: &Site,
    rec: Option<&SegmentRecord>,
    field: Option<&Field>,
    names: &[String],
    settings: &FieldSettings,
    run_id: Option<i64>,
    screened: Option<Screened>,
) -> SiteResult {
    let class_name = site.class.map_or("", |k| names[k].as_str());
    let mut row = FieldSegmentRow {
        segment_id: site.segment_id.clone(),
        label: site.label.clone(),
        soil_class: site.class.map(|k| names[k].clone()),
        label_rejected: site.label_rejected,
        class_overridden: site.class_override.is_some(),
        measured: site.member.is_some(),
        information_scale: site
            .member
            .zip(field)
            .and_then(|(m, f)| f.scales.information.get(m).copied()),
        screen_chi2: screened.map(|s| s.chi2),
        ..FieldSegmentRow::default()
    };
    let none = |mut row: FieldSegmentRow, why: String| {
        row.note = why;
        SiteResult {
            row,
            prediction: None,
        }
    };
    let Some(field) = field else {
        return none(
            row,
            "no fitted segment in the network to learn the soil from".into(),
        );
    };
    let Some(rec) = rec else {
        return none(
            row,
            "not in the inventory when the field was updated".into(),
        );
    };
    let data = match crate::rows::segment_data(rec) {
        Ok(d) => d,
        Err(e) => return none(row, format!("no speed: the pipe's data are unusable ({e})")),
    };
    let own = [(site.class.unwrap_or(0), 1.0)];
    let classes: &[(usize, f64)] = if site.classes.is_empty() {
        &own
    } else {
        &site.classes
    };
    let post = field.mixture_posterior_at(site.pos, classes, site.member, Some(data.soil_density));
    let speed = predict_speed(
        &data,
        settings.model,
        settings.contact_mode,
        post.mean,
        post.cov,
        field.widening,
    );
    let mut note = note_of(site, &post, field, class_name);
    if speed.band.is_some() && speed.band_hz != LEAK_BAND_HZ {
        let _ = write!(
            note,
            "; its wave ends inside the leak band for most of the soils and contacts it may \
             have, so its speed is the mean over {:.0}–{:.0} Hz",
            speed.band_hz.0, speed.band_hz.1
        );
    }
    if site.fitted_speed.is_some() {
        // A measured segment: the leave-one-out check (P82), on the whole leak band only.
        if let Some((b, z)) = site.fitted_speed.and_then(|f| speed.leave_one_out(f)) {
            row.field_leak_band_speed_m_per_s = Some(b.value);
            row.field_leak_band_speed_std_m_per_s = Some(b.std);
            row.loo_z = Some(z);
            row.field_outlier = z.abs() > FIELD_OUTLIER_Z;
        }
        row.note = note;
        return SiteResult {
            row,
            prediction: None,
        };
    }
    if speed.band.is_none() {
        return none(
            row,
            format!("no speed: the forward model has no root for the soil predicted ({note})"),
        );
    }
    row.note.clone_from(&note);
    // The soil's stated errors are the predictive ones (P92).
    let stated = Posterior {
        cov: post.cov.scale_axes(field.widening),
        ..post
    };
    let pred = prediction_row(
        site,
        run_id,
        &stated,
        &speed,
        data.soil_density,
        class_name,
        note,
    );
    SiteResult {
        row,
        prediction: Some((pred, speed.curve)),
    }
}

/// Run `f` in `pool` (the global pool when none could be built: only the speed differs).
fn in_pool<R: Send>(pool: &Option<rayon::ThreadPool>, f: impl FnOnce() -> R + Send) -> R {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Update the soil field after a calibrate run (`run_id`): rebuild it from the stored fits
/// when its inputs changed (or `settings.force`), predict every segment without a fitted speed,
/// check every measured one by leave-one-out, and store it all in place of the previous
/// update's.
pub fn update_field(
    conn: &mut Connection,
    run_id: Option<i64>,
    settings: &FieldSettings,
) -> Result<FieldUpdate, DbError> {
    let started = Instant::now();
    let (fp, (sites, obs, names)) = read_sites(conn, settings)?;
    if !settings.force {
        if let Some(last) = store::latest_field_run(conn)? {
            if last.fingerprint == fp {
                return Ok(FieldUpdate {
                    up_to_date: true,
                    run: last,
                    zones: crate::zones::zones_up_to_date(conn)?,
                });
            }
        }
    }
    let ell_bounds = length_bounds(&sites);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(settings.jobs.max(1))
        .build()
        .ok();
    // The declared zones first: their hierarchical estimates are the zone classes' means.
    let zones_started = Instant::now();
    let zones = crate::zones::estimate_stored_zones(conn)?;
    let zones_s = zones_started.elapsed().as_secs_f64();
    let means = zone_class_means(&names, &zones);
    let obs = at_class_density(obs, &sites, &means);
    let n_members = obs.len();
    let field = in_pool(&pool, || {
        (n_members > 0).then(|| Field::fit_with_means(obs, names.len(), ell_bounds, means))
    });
    let h = field.as_ref().map(|f| f.hyper);
    // Every member's χ² against its leave-one-out prediction: the screening that set the
    // information scales, else (given θ, too few members) one in the final field.
    let screened: Vec<Screened> = in_pool(&pool, || match field.as_ref() {
        Some(f) if !f.screened.is_empty() => f.screened.clone(),
        Some(f) => f.screen(),
        None => Vec::new(),
    });
    let mut run = FieldRunRow {
        id: None,
        run_id,
        fingerprint: fp,
        n_segments: sites.len() as i64,
        n_measured: n_members as i64,
        n_classes: names.len() as i64,
        neighbours: NEIGHBOURS as i64,
        correlation_length_m: h.map(|h| h.ell),
        correlation_length_lo_m: Some(ell_bounds.0),
        correlation_length_hi_m: Some(ell_bounds.1),
        field_cov: [h.map(|h| h.b.pp), h.map(|h| h.b.ps), h.map(|h| h.b.ss)],
        scatter_var: [h.map(|h| h.t.pp), h.map(|h| h.t.ss)],
        log_likelihood: field.as_ref().and_then(|f| f.log_likelihood),
        hyper_source: field
            .as_ref()
            .map_or(model::HyperSource::Defaults, |f| f.source)
            .as_str()
            .to_string(),
        ..FieldRunRow::default()
    };
    let mut classes: Vec<FieldClassRow> = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let members: Vec<&Site> = sites.iter().filter(|s| s.class == Some(k)).collect();
        let (mean, cov) = field.as_ref().map_or(
            (
                model::TYPICAL_LN_SPEEDS,
                Sym2::diag(model::CLASS_PRIOR_SD.powi(2)),
            ),
            |f| f.class(k),
        );
        classes.push(FieldClassRow {
            soil_class: name.clone(),
            n_segments: members.len() as i64,
            n_measured: members.iter().filter(|s| s.member.is_some()).count() as i64,
            mean,
            std: [cov.pp.max(0.0).sqrt(), cov.ss.max(0.0).sqrt()],
            scale: field.as_ref().map_or([1.0, 1.0], |f| f.scales.of_class(k)),
        });
    }
    let by_id: BTreeMap<&str, usize> = sites
        .iter()
        .enumerate()
        .map(|(i, s)| (s.segment_id.as_str(), i))
        .collect();
    let n_with_fit = sites.iter().filter(|s| s.fitted_speed.is_some()).count();
    // The zones are stored before the field: should the field's transaction fail, the next
    // update finds it stale and estimates both again (the stored zones then count up to date).
    let declared = !zones.zones.is_empty() || zones.too_few > 0;
    let zones = if declared {
        Some(crate::zones::store_zones(conn, run_id, &zones, zones_s)?)
    } else {
        None
    };
    // Every site's result, a page of the inventory at a time, stored as it comes (flat memory),
    // all in one transaction: the previous update stays whole until this one is.
    let id = store::in_transaction(conn, |tx| {
        let id = store::start_field(tx, &run, &crate::physics::curves::STANDARD_GRID_HZ)?;
        let mut z: Vec<f64> = Vec::new();
        let (mut predicted, mut class_mean_only, mut outliers, mut rejected) = (0, 0, 0, 0);
        let mut tally = |rows: &[FieldSegmentRow], preds: &[Prediction]| {
            for r in rows {
                // The spread checks the stated errors of the members the field describes
                // (P82); an outlier, flagged and counted beside it, is a record the field does
                // not describe, and one z of −80 would make the spread of 200 members 5.9.
                // Cut at |z| = 3.29 ([`FIELD_OUTLIER_Z`]), N(0, 1)'s spread falls by 0.6 %.
                if !r.field_outlier {
                    z.extend(r.loo_z);
                }
                outliers += usize::from(r.field_outlier);
                rejected += usize::from(r.label_rejected);
            }
            for p in preds {
                predicted += 1;
                class_mean_only += usize::from(sites[by_id[p.0.segment_id.as_str()]].pos.is_none());
            }
        };
        let mut after: Option<String> = None;
        loop {
            let page = pages::segments_page(tx, after.as_deref(), PAGE)?;
            let Some(last) = page.last() else {
                break;
            };
            after = Some(last.segment_id.clone());
            let full = page.len() >= PAGE;
            let results: Vec<(usize, SiteResult)> = in_pool(&pool, || {
                page.par_iter()
                    .filter_map(|rec| by_id.get(rec.segment_id.as_str()).map(|&i| (i, rec)))
                    .map(|(i, rec)| {
                        (
                            i,
                            site_result(
                                &sites[i],
                                Some(rec),
                                field.as_ref(),
                                &names,
                                settings,
                                run_id,
                                sites[i].member.and_then(|m| screened.get(m).copied()),
                            ),
                        )
                    })
                    .collect()
            });
            let mut rows = Vec::with_capacity(results.len());
            let mut preds = Vec::new();
            for (_, r) in results {
                rows.push(r.row);
                preds.extend(r.prediction);
            }
            tally(&rows, &preds);
            store::insert_field_rows(tx, id, &rows, &preds)?;
            if !full {
                break;
            }
        }
        let z_std = (z.len() >= 2).then(|| {
            let m = z.iter().sum::<f64>() / z.len() as f64;
            (z.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (z.len() - 1) as f64).sqrt()
        });
        run.n_predicted = predicted as i64;
        run.n_class_mean_only = class_mean_only as i64;
        run.n_without_speed = (sites.len() - predicted - n_with_fit) as i64;
        run.loo_z_std = z_std;
        run.n_field_outliers = outliers as i64;
        run.n_labels_rejected = rejected as i64;
        run.elapsed_s = Some(started.elapsed().as_secs_f64());
        store::finish_field(tx, id, &run, &classes)?;
        Ok(id)
    })?;
    run.id = Some(id);
    Ok(FieldUpdate {
        up_to_date: false,
        run,
        zones,
    })
}

/// The field of the latest stored update, rebuilt as that update made it (P78–P80): the
/// inventory read one row at a time (no geometry text kept), the update's hyper-parameters,
/// class multipliers and information scales; only the class means are estimated again, from
/// the same fits. Without stored hyper-parameters the field is fitted anew. `None` when there
/// is no update or no measured segment. `plan` and the joint posteriors of `locate` both use
/// it, so they see the field the predictions came from.
pub fn stored_field(
    conn: &Connection,
    pool: &Option<rayon::ThreadPool>,
) -> Result<Option<(crate::db::field::FieldRunRow, Field, Vec<Site>)>, DbError> {
    use crate::db::field as store;
    let Some(last) = store::latest_field_run(conn)? else {
        return Ok(None);
    };
    let (sites, soils) = read_sites_and_soils(conn, |_| {})?;
    let (sites, obs, names) = classes_and_members(sites, &soils);
    if obs.is_empty() {
        return Ok(None);
    }
    let zones = crate::zones::estimate_stored_zones(conn)?;
    let means = zone_class_means(&names, &zones);
    let obs = at_class_density(obs, &sites, &means);
    let bounds = length_bounds(&sites);
    let class_scales = match last.id {
        Some(id) => store::field_class_scales(conn, id)?,
        None => BTreeMap::new(),
    };
    let stored: BTreeMap<String, f64> = store::field_segments(conn)?
        .into_iter()
        .filter_map(|r| r.information_scale.map(|s| (r.segment_id, s)))
        .collect();
    let mut information = vec![1.0; obs.len()];
    for s in &sites {
        if let (Some(m), Some(&v)) = (s.member, stored.get(&s.segment_id)) {
            information[m] = v;
        }
    }
    let scales = model::Scales {
        class: names
            .iter()
            .map(|n| class_scales.get(n).copied().unwrap_or([1.0, 1.0]))
            .collect(),
        information,
        means,
    };
    let source = if last.hyper_source == model::HyperSource::Defaults.as_str() {
        model::HyperSource::Defaults
    } else {
        model::HyperSource::MarginalLikelihood
    };
    let nk = names.len();
    let field = in_pool(pool, || match joint::stored_hyper(&last) {
        Some(h) => Field::with_scales(obs, nk, bounds, h, source, scales),
        None => Field::fit(obs, nk, bounds),
    });
    Ok(Some((last, field, sites)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A segment on a straight street at `x` m with a label and, optionally, an override.
    fn input(id: &str, x: f64, label: &str, over: Option<&str>) -> FieldInput {
        FieldInput {
            segment_id: id.into(),
            geometry_wkt: Some(format!("LINESTRING ({x} 0, {} 0)", x + 40.0)),
            srid: Some(27700),
            soil_type: Some(label.into()),
            material: "PVC".into(),
            soil_zone: None,
            length_m: None,
            risk_weight: None,
            soil_class_override: over.map(str::to_string),
            inputs_hash: "h".into(),
            fit_id: None,
            fit_status: None,
            speeds: None,
            information: None,
            leak_band_speed: None,
            soil_density: Some(1800.0),
            fit_findings: String::new(),
        }
    }

    /// An override keeps its class (a class no other segment carries) with certainty inside a
    /// unit whose labels would otherwise overrule it, and is not counted as rejected; the same
    /// segment without the override takes its neighbourhood's class and is reported.
    #[test]
    fn an_override_sets_the_class_with_certainty() {
        let mk = |over: Option<&str>| -> Vec<FieldInput> {
            (0..20)
                .map(|i| {
                    let o = if i == 10 { over } else { None };
                    input(&format!("S{i:02}"), 50.0 * i as f64, "clay", o)
                })
                .collect()
        };
        let (sites, _, names) = sites_of(&mk(Some("peat")));
        let s = &sites[10];
        assert_eq!(names[s.class.unwrap()], "peat");
        assert_eq!(s.classes, vec![(s.class.unwrap(), 1.0)]);
        assert!(!s.label_rejected);
        assert!(sites.iter().all(|t| !t.label_rejected));
        assert_eq!(sites[9].class, sites[11].class);
        assert_eq!(names[sites[9].class.unwrap()], "clay");

        // Without it, a lone "peat" label is rejected by its clay neighbourhood.
        let mut plain = mk(None);
        plain[10].soil_type = Some("peat".into());
        let (sites, _, names) = sites_of(&plain);
        assert_eq!(names[sites[10].class.unwrap()], "clay");
        assert!(sites[10].label_rejected);
    }

    /// A fit is suspect when it notes its wave near grazing (any pipe) or, on a metal pipe, its
    /// soil undetermined; a plastic pipe's undetermined soil is not.
    #[test]
    fn suspect_fits_follow_their_findings() {
        assert!(suspect_fit("PVC", "speed_uncertain,near_grazing"));
        assert!(suspect_fit("CI", "near_grazing"));
        assert!(suspect_fit("DI", ",soil_undetermined,contact_undetermined"));
        assert!(!suspect_fit(
            "MDPE",
            "soil_undetermined,contact_undetermined"
        ));
        assert!(!suspect_fit("ST", "soil_via_cp,at_bound"));
        assert!(!suspect_fit("ST", "near_grazing_x"));
        assert!(!suspect_fit("CI", ""));
    }

    /// The fingerprint changes with an override and, without one, is what it was before the
    /// column existed (a network without overrides is not rebuilt after an upgrade).
    #[test]
    fn the_fingerprint_follows_the_override_only_where_given() {
        let settings = FieldSettings {
            model: Model::Full,
            contact_mode: ContactMode::Reciprocal,
            jobs: 1,
            force: false,
        };
        let plain = input("S1", 0.0, "clay", None);
        let mut fp = Fingerprint::new(&settings);
        fp.add(&plain);
        let head = format!(
            "field v{FIELD_ALGORITHM_VERSION} {} {}\n",
            settings.model.as_str(),
            settings.contact_mode.as_str()
        );
        let line = format!(
            "{}|{}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}\n",
            plain.segment_id,
            plain.inputs_hash,
            plain.soil_type,
            plain.soil_zone,
            plain.geometry_wkt,
            plain.srid,
            plain.length_m,
            plain.fit_id
        );
        assert_eq!(fp.0, fnv1a64(format!("{head}{line}").as_bytes()));
        let mut over = Fingerprint::new(&settings);
        over.add(&input("S1", 0.0, "clay", Some("peat")));
        assert_ne!(over.0, fp.0);
        let mut weighted = Fingerprint::new(&settings);
        let mut w = plain.clone();
        w.risk_weight = Some(3.0);
        weighted.add(&w);
        assert_eq!(weighted.0, fp.0);
    }
}
