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

#[cfg(test)]
mod tests {
    use super::*;

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
