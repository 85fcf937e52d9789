//! The exported properties, in order, with their types ([`PROPERTIES`]): the GeoPackage
//! columns, the GeoJSON properties and the CSV columns are all made from this one list, so the
//! three formats cannot drift apart. Each property reads its value from a
//! [`SegmentExport`].

use super::record::SegmentExport;
use crate::db::{self, FitRow};

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
