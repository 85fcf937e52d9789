//! Coordinate reference systems: EPSG definitions (WKT for the GeoPackage, proj4 strings for
//! reprojection) from the `crs-definitions` crate, and reprojection with `proj4rs`.
//!
//! `crs-definitions` carries the EPSG registry's projected and geographic systems (several
//! thousand, including British National Grid 27700, ETRS89/UTM 25832/25833, Web Mercator 3857,
//! Lambert-93 2154, WGS 84/UTM 32630–32633 and NAD83/UTM 26910–26919), so no table of our own is
//! kept. A code it does not know gets the `undefined` definition and a warning.
//!
//! Datum shifts are the proj4 `+towgs84` seven-parameter (Helmert) transformations of those
//! definitions. For OSGB36 this is the Ordnance Survey's published Helmert, good to a few metres
//! (OSTN15 grid shifts would give centimetres but need a grid file): ample to place a pipe on a
//! map, and the GeoPackage keeps the original coordinates untouched.

use std::collections::HashMap;

use proj4rs::proj::Proj;

use crate::db::wkt::LineString;
use crate::units::short;

/// EPSG code of WGS 84 longitude/latitude, the only CRS of RFC 7946 GeoJSON.
pub const WGS84: i64 = 4326;

/// An EPSG coordinate reference system as far as the exports need it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CrsDef {
    /// EPSG code.
    pub srid: i64,
    /// Its name, e.g. `OSGB 1936 / British National Grid`.
    pub name: &'static str,
    /// OGC WKT (version 1) definition.
    pub wkt: &'static str,
    /// proj4 string.
    pub proj4: &'static str,
}

/// The definition of an EPSG code, if `crs-definitions` knows it.
pub fn lookup(srid: i64) -> Option<CrsDef> {
    let code = u16::try_from(srid).ok()?;
    let def = crs_definitions::from_code(code)?;
    Some(CrsDef {
        srid,
        name: wkt_name(def.wkt).unwrap_or("unnamed"),
        wkt: def.wkt,
        proj4: def.proj4,
    })
}

/// The first quoted string of a WKT definition: the CRS name.
fn wkt_name(wkt: &'static str) -> Option<&'static str> {
    let start = wkt.find('"')? + 1;
    let len = wkt[start..].find('"')?;
    Some(&wkt[start..start + len])
}

/// Why a reprojection is not possible.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CrsError {
    /// The EPSG code is not in the built-in registry.
    #[error("EPSG:{0} is not a coordinate system pipewave knows")]
    Unknown(i64),
    /// proj4rs could not use the definition.
    #[error("EPSG:{srid} cannot be used for reprojection: {message}")]
    Unusable {
        /// EPSG code.
        srid: i64,
        /// What proj4rs said.
        message: String,
    },
    /// A point could not be transformed.
    #[error("a point could not be transformed from EPSG:{from} to EPSG:{to}: {message}")]
    Transform {
        /// Source EPSG code.
        from: i64,
        /// Target EPSG code.
        to: i64,
        /// What proj4rs said.
        message: String,
    },
}

fn proj_for(srid: i64) -> Result<Proj, CrsError> {
    let def = lookup(srid).ok_or(CrsError::Unknown(srid))?;
    Proj::from_proj_string(def.proj4).map_err(|e| CrsError::Unusable {
        srid,
        message: e.to_string(),
    })
}

/// A transformation from one EPSG system to another, in degrees for geographic systems
/// (x = longitude, y = latitude) and in the system's units otherwise.
#[derive(Debug)]
pub struct Reprojector {
    from: i64,
    to: i64,
    src: Proj,
    dst: Proj,
}

impl Reprojector {
    /// Prepare the transformation `from` → `to`.
    pub fn new(from: i64, to: i64) -> Result<Reprojector, CrsError> {
        Ok(Reprojector {
            from,
            to,
            src: proj_for(from)?,
            dst: proj_for(to)?,
        })
    }

    /// Transform one point.
    pub fn point(&self, (x, y): (f64, f64)) -> Result<(f64, f64), CrsError> {
        if self.from == self.to {
            return Ok((x, y));
        }
        let mut p = if self.src.is_latlong() {
            (x.to_radians(), y.to_radians(), 0.0)
        } else {
            (x, y, 0.0)
        };
        proj4rs::transform::transform(&self.src, &self.dst, &mut p).map_err(|e| {
            CrsError::Transform {
                from: self.from,
                to: self.to,
                message: e.to_string(),
            }
        })?;
        let out = if self.dst.is_latlong() {
            (p.0.to_degrees(), p.1.to_degrees())
        } else {
            (p.0, p.1)
        };
        if out.0.is_finite() && out.1.is_finite() {
            Ok(out)
        } else {
            Err(CrsError::Transform {
                from: self.from,
                to: self.to,
                message: format!("({x}, {y}) has no finite image"),
            })
        }
    }

    /// Transform every vertex of a line.
    pub fn line(&self, line: &LineString) -> Result<LineString, CrsError> {
        let points = line
            .points
            .iter()
            .map(|&p| self.point(p))
            .collect::<Result<_, _>>()?;
        Ok(LineString { points })
    }
}

/// Reprojects segments' geometries into one target system, preparing each source system once.
/// A source that cannot be used is remembered, so each problem is reported once.
#[derive(Debug)]
pub struct ToCommonCrs {
    target: i64,
    cache: HashMap<i64, Result<Reprojector, CrsError>>,
}

impl ToCommonCrs {
    /// Into EPSG:`target`.
    pub fn new(target: i64) -> ToCommonCrs {
        ToCommonCrs {
            target,
            cache: HashMap::new(),
        }
    }

    /// The target EPSG code.
    pub fn target(&self) -> i64 {
        self.target
    }

    /// `line` (in EPSG:`from`) in the target system.
    pub fn line(&mut self, from: i64, line: &LineString) -> Result<LineString, CrsError> {
        if from == self.target {
            return Ok(line.clone());
        }
        let target = self.target;
        match self
            .cache
            .entry(from)
            .or_insert_with(|| Reprojector::new(from, target))
        {
            Ok(r) => r.line(line),
            Err(e) => Err(e.clone()),
        }
    }
}

/// The system most segments' geometries are in (ties: the smallest code), or `None` when no
/// segment has a geometry. Used as the GeoPackage's and the map's single coordinate system.
pub fn dominant_srid<'a>(srids: impl Iterator<Item = i64> + 'a) -> Option<i64> {
    let mut counts: HashMap<i64, usize> = HashMap::new();
    for s in srids {
        *counts.entry(s).or_default() += 1;
    }
    dominant_of_counts(counts)
}

/// [`dominant_srid`] from (system, number of segments) pairs, each system once.
pub fn dominant_of_counts(counts: impl IntoIterator<Item = (i64, usize)>) -> Option<i64> {
    counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map(|(s, _)| s)
}

/// Whether EPSG:`srid` is a geographic (longitude/latitude) system.
pub fn is_geographic(srid: i64) -> bool {
    lookup(srid).is_some_and(|d| d.proj4.contains("+proj=longlat"))
}

/// Largest coordinate magnitude accepted in a projected system, in metres (a coordinate in
/// feet or links is converted first, [`metres_per_unit`]).
///
/// A point on Earth is at most half the equator, 20 037 508 m (Web Mercator's x range), from a
/// projection's natural origin, and the false origins of the EPSG registry add at most
/// 64 500 000 m (the zone-prefixed eastings of the 3-degree Gauss–Krüger zones, e.g. EPSG:2581).
/// So every projected coordinate of a real pipe is below 8.5e7 m in magnitude (a unit test
/// checks this against every definition pipewave knows), and 1e8 m leaves room while still
/// refusing a misplaced exponent or a sentinel value such as 1e308, whose differences would
/// overflow any length.
pub const MAX_PROJECTED_COORDINATE: f64 = 1e8;

/// Metres per coordinate unit of EPSG:`srid` (proj4's `+to_meter`, else its `+units`; 1 when
/// it names none), or `None` for a code pipewave does not know. Degrees of a geographic
/// system are not lengths: this is for projected systems.
pub fn metres_per_unit(srid: i64) -> Option<f64> {
    let p = lookup(srid)?.proj4;
    let value = |key: &str| p.split_whitespace().find_map(|t| t.strip_prefix(key));
    if let Some(k) = value("+to_meter=").and_then(|k| k.parse().ok()) {
        return Some(k);
    }
    // proj4's unit names (`proj -lu`).
    Some(match value("+units=") {
        Some("km") => 1000.0,
        Some("ft") => 0.3048,
        Some("us-ft") => 1200.0 / 3937.0,
        Some("ind-ft") => 0.304_799_51,
        Some("yd") => 0.9144,
        Some("ind-yd") => 0.914_398_53,
        Some("link") => 0.201_168,
        Some("ch") => 20.1168,
        Some("us-ch") => 20.116_84,
        _ => 1.0,
    })
}

/// Largest |longitude| of a geographic system, degrees.
pub const MAX_LONGITUDE: f64 = 180.0;
/// Largest |latitude| of a geographic system, degrees.
pub const MAX_LATITUDE: f64 = 90.0;

/// Why a line cannot be a segment's geometry in EPSG:`srid`, or `Ok`: the system must be one
/// pipewave knows, every vertex within the system's possible coordinates (|lon| ≤ 180°,
/// |lat| ≤ 90° in a geographic system; |x|, |y| ≤ [`MAX_PROJECTED_COORDINATE`] in a projected
/// one), and the line must have a length ([`LineString::check_length`]).
pub fn check_line(srid: i64, line: &LineString) -> Result<(), String> {
    let Some(def) = lookup(srid) else {
        return Err(format!(
            "{}: give an EPSG code of the registry, such as 27700 or 4326",
            CrsError::Unknown(srid)
        ));
    };
    let geographic = def.proj4.contains("+proj=longlat");
    let metres = metres_per_unit(srid).unwrap_or(1.0);
    for &(x, y) in &line.points {
        if !(x.is_finite() && y.is_finite()) {
            return Err(format!(
                "the vertex ({} {}) is not a pair of finite numbers",
                short(x),
                short(y)
            ));
        }
        if geographic && (x.abs() > MAX_LONGITUDE || y.abs() > MAX_LATITUDE) {
            return Err(format!(
                "the vertex ({} {}) is not a longitude and latitude, although EPSG:{srid} ({}) \
                 is a longitude/latitude system (|lon| <= 180, |lat| <= 90); if the coordinates \
                 are in a projected system, give its EPSG code",
                short(x),
                short(y),
                def.name
            ));
        }
        let scale = if geographic { 1.0 } else { metres };
        if (x * scale).abs() > MAX_PROJECTED_COORDINATE
            || (y * scale).abs() > MAX_PROJECTED_COORDINATE
        {
            return Err(format!(
                "the vertex ({} {}) is farther from the origin of EPSG:{srid} ({}) than any \
                 point on Earth (|x|, |y| <= {MAX_PROJECTED_COORDINATE:e} m in any projected \
                 system)",
                short(x),
                short(y),
                def.name
            ));
        }
    }
    line.check_length()
}

/// A stored geometry as the commands use it: `wkt` parsed and, with its system, checked by
/// [`check_line`]. Without a system only the parse, the finiteness bound of a projected system
/// and the length are checked. `Err` says why it cannot be used.
pub fn usable_line(wkt: &str, srid: Option<i64>) -> Result<LineString, String> {
    let line = LineString::parse_wkt(wkt)?;
    match srid {
        Some(s) => check_line(s, &line)?,
        None => {
            if let Some((x, y)) = line.points.iter().find(|(x, y)| {
                x.abs() > MAX_PROJECTED_COORDINATE || y.abs() > MAX_PROJECTED_COORDINATE
            }) {
                return Err(format!(
                    "the vertex ({} {}) is farther from the origin than any point on Earth in \
                     any projected system",
                    short(*x),
                    short(*y)
                ));
            }
            line.check_length()?;
        }
    }
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`MAX_PROJECTED_COORDINATE`] holds for every projected system pipewave knows: its false
    /// easting and northing (metres in proj4) plus half the equator (the farthest a point on
    /// Earth is from the natural origin) stay below it.
    #[test]
    fn no_projected_system_has_coordinates_near_the_bound() {
        const HALF_EQUATOR_M: f64 = 20_037_508.34;
        let param = |p: &str, key: &str| -> Option<f64> {
            p.split_whitespace()
                .find_map(|t| t.strip_prefix(key))
                .and_then(|v| v.parse().ok())
        };
        let mut largest: f64 = 0.0;
        let mut projected = 0;
        for code in 1..=u16::MAX {
            let Some(def) = lookup(i64::from(code)) else {
                continue;
            };
            if def.proj4.contains("+proj=longlat") || def.proj4.contains("+proj=geocent") {
                continue;
            }
            projected += 1;
            assert!(metres_per_unit(i64::from(code)).is_some_and(|m| m > 0.0));
            for key in ["+x_0=", "+y_0="] {
                let reach = param(def.proj4, key).unwrap_or(0.0).abs() + HALF_EQUATOR_M;
                largest = largest.max(reach);
            }
        }
        assert!(projected > 1000, "{projected} projected systems");
        assert!(largest < MAX_PROJECTED_COORDINATE, "{largest}");
        assert!(largest > 0.5 * MAX_PROJECTED_COORDINATE, "{largest}");
    }

    #[test]
    fn lines_are_checked_against_their_system() {
        let line = |pts: &[(f64, f64)]| LineString {
            points: pts.to_vec(),
        };
        let bng = line(&[(530_000.0, 180_000.0), (530_100.0, 180_000.0)]);
        assert!(check_line(27700, &bng).is_ok());
        let e = check_line(4326, &bng).unwrap_err();
        assert!(e.contains("not a longitude and latitude"), "{e}");
        let e = check_line(999_999, &bng).unwrap_err();
        assert!(e.contains("EPSG:999999 is not a coordinate system"), "{e}");
        assert!(check_line(4326, &line(&[(-0.1, 51.5), (-0.1, 51.6)])).is_ok());
        // 3e8 US survey feet is 9.1e7 m: on Earth for the bound; 3.3e8 ft is not.
        assert!(check_line(2227, &line(&[(3e8, 0.0), (0.0, 0.0)])).is_ok());
        assert!(check_line(2227, &line(&[(3.3e8, 0.0), (0.0, 0.0)])).is_err());
        let far = line(&[(1e308, 0.0), (0.0, 0.0)]);
        let e = check_line(27700, &far).unwrap_err();
        assert!(e.contains("than any point on Earth"), "{e}");
        assert!(usable_line("LINESTRING (1e308 0, 0 0)", None).is_err());
        let e = check_line(27700, &line(&[(1.0, 2.0), (1.0, 2.0)])).unwrap_err();
        assert!(e.contains("zero length"), "{e}");
        assert_eq!(
            usable_line("LINESTRING (1 2, 3 4)", Some(27700)).unwrap(),
            line(&[(1.0, 2.0), (3.0, 4.0)])
        );
    }

    /// The projected systems utilities commonly use: each must have a projected WKT whose authority is its code.
    #[test]
    fn the_common_projected_systems_are_known() {
        let mut codes = vec![27700, 25832, 25833, 3857, 2154];
        codes.extend(32630..=32633);
        codes.extend(26910..=26919);
        for c in codes {
            let d = lookup(c).unwrap_or_else(|| panic!("EPSG:{c} missing"));
            assert!(d.wkt.starts_with("PROJCS["), "{c}: {}", d.wkt);
            assert!(
                d.wkt.ends_with(&format!("AUTHORITY[\"EPSG\",\"{c}\"]]")),
                "{c}: {}",
                d.wkt
            );
            assert!(!d.proj4.is_empty());
            assert!(!is_geographic(c));
        }
        assert_eq!(
            lookup(27700).unwrap().name,
            "OSGB 1936 / British National Grid"
        );
        assert!(is_geographic(4326));
        assert!(lookup(999_999).is_none());
        assert!(lookup(-1).is_none());
    }

    /// Ordnance Survey, "A guide to coordinate systems in Great Britain" (v3.6), annex C worked
    /// example: Caister Water Tower, OSGB36 latitude 52°39′27.2531″N, longitude 1°43′4.5177″E is
    /// E 651409.903, N 313177.270 on the National Grid. A pure projection (no datum shift), so it
    /// checks proj4rs's Transverse Mercator and our degree/radian handling to the millimetre.
    #[test]
    fn national_grid_projection_matches_the_os_worked_example() {
        const OSGB36_LONLAT: i64 = 4277;
        let r = Reprojector::new(27700, OSGB36_LONLAT).unwrap();
        let (lon, lat) = r.point((651_409.903, 313_177.270)).unwrap();
        let lat_ref = 52.0 + 39.0 / 60.0 + 27.2531 / 3600.0;
        let lon_ref = 1.0 + 43.0 / 60.0 + 4.5177 / 3600.0;
        // 1e-7 degree is about 1 cm.
        assert!((lat - lat_ref).abs() < 1e-7, "{lat} vs {lat_ref}");
        assert!((lon - lon_ref).abs() < 1e-7, "{lon} vs {lon_ref}");
        let back = Reprojector::new(OSGB36_LONLAT, 27700)
            .unwrap()
            .point((lon_ref, lat_ref))
            .unwrap();
        assert!((back.0 - 651_409.903).abs() < 0.01, "{back:?}");
        assert!((back.1 - 313_177.270).abs() < 0.01, "{back:?}");
    }

    #[test]
    fn unknown_systems_are_errors_not_panics() {
        assert_eq!(
            Reprojector::new(999_999, WGS84).unwrap_err(),
            CrsError::Unknown(999_999)
        );
        let mut c = ToCommonCrs::new(WGS84);
        let l = LineString {
            points: vec![(0.0, 0.0), (1.0, 1.0)],
        };
        assert!(c.line(999_999, &l).is_err());
        assert!(c.line(999_999, &l).is_err());
        assert_eq!(c.line(WGS84, &l).unwrap(), l);
    }

    #[test]
    fn dominant_srid_is_the_most_common() {
        assert_eq!(dominant_srid([27700, 4326, 27700].into_iter()), Some(27700));
        assert_eq!(dominant_srid([4326, 27700].into_iter()), Some(4326));
        assert_eq!(dominant_srid(std::iter::empty()), None);
    }
}
