//! The standard pipe catalogues the inventory check draws its candidate records from (model §8
//! E8): one table, [`CATALOGUE`], of series (material, standard, class) with their sizes, each
//! with the published source its numbers were typed from. The sizes the utility's own
//! inventory holds are added at diagnosis time ([`super::inventory::InventoryProfile`]).
//!
//! Plastic walls follow the ISO 4065 pipe series, which ISO 4427 (PE) and EN 1452 (PVC-U) both
//! use: at one outside diameter and SDR a PE and a PVC-U pipe have the same nominal wall, so
//! the walls by SDR are typed once and shared. Iron walls follow the standards' formulas:
//! ductile iron (ISO 2531) e = K(0.5 + 0.001 DN) with a minimum wall, grey iron (ISO 13)
//! e = k(7 + 0.02 DN) with k = 1 for class A and 1.1 for class B.

use crate::physics::Material;

/// One catalogue size: nominal size DN (mm), outside diameter and nominal wall (mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Size {
    /// Nominal size DN, mm (for plastics the nominal size is the outside diameter).
    pub dn: f64,
    /// Outside diameter, mm.
    pub od_mm: f64,
    /// Nominal wall thickness, mm.
    pub wall_mm: f64,
}

/// A series of one standard: material, class, sizes and where the numbers come from.
#[derive(Debug, Clone, Copy)]
pub struct Series {
    /// Material.
    pub material: Material,
    /// Standard.
    pub standard: &'static str,
    /// Class within the standard (SDR, K class, pressure class).
    pub class: &'static str,
    /// The published table the sizes were typed from.
    pub source: &'static str,
    /// Sizes.
    pub sizes: &'static [Size],
}

const fn s(dn: f64, od_mm: f64, wall_mm: f64) -> Size {
    Size { dn, od_mm, wall_mm }
}

/// Plastic size: the nominal size is the outside diameter.
const fn p(od_mm: f64, wall_mm: f64) -> Size {
    s(od_mm, od_mm, wall_mm)
}

/// Round to 0.1 mm, half up (walls are published to 0.1 mm).
const fn round1(x: f64) -> f64 {
    ((x * 10.0 + 0.5) as i64) as f64 / 10.0
}

/// Ductile iron, ISO 2531: e = K(0.5 + 0.001 DN), at least `min_mm`.
const fn di(k: f64, min_mm: f64, dn: f64, od_mm: f64) -> Size {
    let e = round1(k * (0.5 + 0.001 * dn));
    s(dn, od_mm, if e < min_mm { min_mm } else { e })
}

/// Grey iron, ISO 13: e = k(7 + 0.02 DN).
const fn ci(k: f64, dn: f64, od_mm: f64) -> Size {
    s(dn, od_mm, round1(k * (7.0 + 0.02 * dn)))
}

const PE_SOURCE: &str = "ISO 4427-2:2007 Table 2 (walls of the ISO 4065 series), as tabulated in \
                         manufacturers' PE100/PE80 catalogues (e.g. Vesbo HDPE brochure p. 3)";
const PVC_SOURCE: &str = "EN 1452-2:2009 Table 2 (walls of the ISO 4065 series), as tabulated in \
                          manufacturers' PVC-U pressure pipe catalogues";

/// SDR 11 walls (ISO 4065 series S 5), OD 63–400 mm.
const SDR11: [Size; 15] = [
    p(63.0, 5.8),
    p(75.0, 6.8),
    p(90.0, 8.2),
    p(110.0, 10.0),
    p(125.0, 11.4),
    p(140.0, 12.7),
    p(160.0, 14.6),
    p(180.0, 16.4),
    p(200.0, 18.2),
    p(225.0, 20.5),
    p(250.0, 22.7),
    p(280.0, 25.4),
    p(315.0, 28.6),
    p(355.0, 32.2),
    p(400.0, 36.3),
];
/// SDR 17 walls (S 8).
const SDR17: [Size; 15] = [
    p(63.0, 3.8),
    p(75.0, 4.5),
    p(90.0, 5.4),
    p(110.0, 6.6),
    p(125.0, 7.4),
    p(140.0, 8.3),
    p(160.0, 9.5),
    p(180.0, 10.7),
    p(200.0, 11.9),
    p(225.0, 13.4),
    p(250.0, 14.8),
    p(280.0, 16.6),
    p(315.0, 18.7),
    p(355.0, 21.1),
    p(400.0, 23.7),
];
/// SDR 21 walls (S 10).
const SDR21: [Size; 15] = [
    p(63.0, 3.0),
    p(75.0, 3.6),
    p(90.0, 4.3),
    p(110.0, 5.3),
    p(125.0, 6.0),
    p(140.0, 6.7),
    p(160.0, 7.7),
    p(180.0, 8.6),
    p(200.0, 9.6),
    p(225.0, 10.8),
    p(250.0, 11.9),
    p(280.0, 13.4),
    p(315.0, 15.0),
    p(355.0, 16.9),
    p(400.0, 19.1),
];
/// SDR 26 walls (S 12.5).
const SDR26: [Size; 15] = [
    p(63.0, 2.5),
    p(75.0, 2.9),
    p(90.0, 3.5),
    p(110.0, 4.2),
    p(125.0, 4.8),
    p(140.0, 5.4),
    p(160.0, 6.2),
    p(180.0, 6.9),
    p(200.0, 7.7),
    p(225.0, 8.6),
    p(250.0, 9.6),
    p(280.0, 10.7),
    p(315.0, 12.1),
    p(355.0, 13.6),
    p(400.0, 15.3),
];
/// SDR 33 walls (S 16).
const SDR33: [Size; 15] = [
    p(63.0, 2.0),
    p(75.0, 2.3),
    p(90.0, 2.8),
    p(110.0, 3.4),
    p(125.0, 3.9),
    p(140.0, 4.3),
    p(160.0, 4.9),
    p(180.0, 5.5),
    p(200.0, 6.2),
    p(225.0, 6.9),
    p(250.0, 7.7),
    p(280.0, 8.6),
    p(315.0, 9.7),
    p(355.0, 10.9),
    p(400.0, 12.3),
];
/// SDR 41 walls (S 20).
const SDR41: [Size; 15] = [
    p(63.0, 1.6),
    p(75.0, 1.9),
    p(90.0, 2.2),
    p(110.0, 2.7),
    p(125.0, 3.1),
    p(140.0, 3.5),
    p(160.0, 4.0),
    p(180.0, 4.4),
    p(200.0, 4.9),
    p(225.0, 5.5),
    p(250.0, 6.2),
    p(280.0, 6.9),
    p(315.0, 7.7),
    p(355.0, 8.7),
    p(400.0, 9.8),
];

const DI_SOURCE: &str = "ISO 2531:1998 clause 4.3 (e = K(0.5 + 0.001 DN), minimum 6 mm for K9 \
                         and K10, 5 mm for K7) and Table 2 outside diameters, as in ductile-iron \
                         manufacturers' K-class tables (e.g. Saint-Gobain PAM)";

macro_rules! di_series {
    ($k:expr, $min:expr) => {
        [
            di($k, $min, 80.0, 98.0),
            di($k, $min, 100.0, 118.0),
            di($k, $min, 125.0, 144.0),
            di($k, $min, 150.0, 170.0),
            di($k, $min, 200.0, 222.0),
            di($k, $min, 250.0, 274.0),
            di($k, $min, 300.0, 326.0),
            di($k, $min, 350.0, 378.0),
            di($k, $min, 400.0, 429.0),
            di($k, $min, 450.0, 480.0),
            di($k, $min, 500.0, 532.0),
        ]
    };
}
const DI_K7: [Size; 11] = di_series!(7.0, 5.0);
const DI_K9: [Size; 11] = di_series!(9.0, 6.0);
const DI_K10: [Size; 11] = di_series!(10.0, 6.0);

const CI_SOURCE: &str = "ISO 13:1978 (grey iron pressure pipes: e = k(7 + 0.02 DN), k = 1 class \
                         A, 1.1 class B; outside diameters of its Table 1, shared with ISO 2531)";

macro_rules! ci_series {
    ($k:expr) => {
        [
            ci($k, 80.0, 98.0),
            ci($k, 100.0, 118.0),
            ci($k, 125.0, 144.0),
            ci($k, 150.0, 170.0),
            ci($k, 200.0, 222.0),
            ci($k, 250.0, 274.0),
            ci($k, 300.0, 326.0),
            ci($k, 350.0, 378.0),
            ci($k, 400.0, 429.0),
        ]
    };
}
const CI_A: [Size; 9] = ci_series!(1.0);
const CI_B: [Size; 9] = ci_series!(1.1);

const ST_SOURCE: &str = "EN 10224:2002 outside diameters (EN 10220 series 1) with wall \
                         thicknesses of the EN 10220 preferred series within the range EN \
                         10224 lists for each diameter (thin, common, thick)";

/// Steel water pipe, EN 10224: three walls per outside diameter.
const ST: [Size; 27] = [
    s(80.0, 88.9, 3.2),
    s(80.0, 88.9, 4.0),
    s(80.0, 88.9, 5.0),
    s(100.0, 114.3, 3.6),
    s(100.0, 114.3, 4.5),
    s(100.0, 114.3, 5.6),
    s(125.0, 139.7, 4.0),
    s(125.0, 139.7, 5.0),
    s(125.0, 139.7, 6.3),
    s(150.0, 168.3, 4.5),
    s(150.0, 168.3, 5.6),
    s(150.0, 168.3, 7.1),
    s(200.0, 219.1, 5.0),
    s(200.0, 219.1, 6.3),
    s(200.0, 219.1, 8.0),
    s(250.0, 273.0, 5.6),
    s(250.0, 273.0, 7.1),
    s(250.0, 273.0, 8.8),
    s(300.0, 323.9, 5.6),
    s(300.0, 323.9, 7.1),
    s(300.0, 323.9, 8.8),
    s(350.0, 355.6, 6.3),
    s(350.0, 355.6, 8.0),
    s(350.0, 355.6, 10.0),
    s(400.0, 406.4, 6.3),
    s(400.0, 406.4, 8.8),
    s(400.0, 406.4, 10.0),
];

const AC_SOURCE: &str = "ISO 160:1980 pressure classes 10/15/20/25 (DN = bore, OD = DN + 2e); \
                         walls from class-20 manufacturers' sizes scaled by the class's test \
                         pressure with the hoop-stress relation above a minimum wall: the \
                         least certain series of the table";

/// Asbestos cement, one pressure class: walls for DN 80, 100, 125, 150, 200, 250, 300.
macro_rules! ac_series {
    ($w:expr) => {{
        const W: [f64; 7] = $w;
        [
            s(80.0, 80.0 + 2.0 * W[0], W[0]),
            s(100.0, 100.0 + 2.0 * W[1], W[1]),
            s(125.0, 125.0 + 2.0 * W[2], W[2]),
            s(150.0, 150.0 + 2.0 * W[3], W[3]),
            s(200.0, 200.0 + 2.0 * W[4], W[4]),
            s(250.0, 250.0 + 2.0 * W[5], W[5]),
            s(300.0, 300.0 + 2.0 * W[6], W[6]),
        ]
    }};
}
const AC10: [Size; 7] = ac_series!([8.5, 9.0, 9.5, 10.0, 11.0, 13.0, 15.0]);
const AC15: [Size; 7] = ac_series!([9.5, 10.0, 11.0, 12.0, 14.0, 16.5, 19.5]);
const AC20: [Size; 7] = ac_series!([10.5, 11.5, 12.5, 14.0, 17.0, 20.5, 24.0]);
const AC25: [Size; 7] = ac_series!([12.0, 13.5, 15.0, 17.0, 21.0, 25.5, 30.0]);

macro_rules! series {
    ($m:expr, $std:expr, $class:expr, $src:expr, $sizes:expr) => {
        Series {
            material: $m,
            standard: $std,
            class: $class,
            source: $src,
            sizes: &$sizes,
        }
    };
}

/// The candidate-record catalogue: every series of the standards named in model §8 E8's
/// candidates, with its source.
pub const CATALOGUE: [Series; 21] = [
    series!(Material::Mdpe, "ISO 4427", "SDR 11", PE_SOURCE, SDR11),
    series!(Material::Mdpe, "ISO 4427", "SDR 17", PE_SOURCE, SDR17),
    series!(Material::Mdpe, "ISO 4427", "SDR 26", PE_SOURCE, SDR26),
    series!(Material::Hdpe, "ISO 4427", "SDR 11", PE_SOURCE, SDR11),
    series!(Material::Hdpe, "ISO 4427", "SDR 17", PE_SOURCE, SDR17),
    series!(Material::Hdpe, "ISO 4427", "SDR 26", PE_SOURCE, SDR26),
    series!(Material::Pvc, "EN 1452", "SDR 17", PVC_SOURCE, SDR17),
    series!(Material::Pvc, "EN 1452", "SDR 21", PVC_SOURCE, SDR21),
    series!(Material::Pvc, "EN 1452", "SDR 26", PVC_SOURCE, SDR26),
    series!(Material::Pvc, "EN 1452", "SDR 33", PVC_SOURCE, SDR33),
    series!(Material::Pvc, "EN 1452", "SDR 41", PVC_SOURCE, SDR41),
    series!(Material::DuctileIron, "ISO 2531", "K7", DI_SOURCE, DI_K7),
    series!(Material::DuctileIron, "ISO 2531", "K9", DI_SOURCE, DI_K9),
    series!(Material::DuctileIron, "ISO 2531", "K10", DI_SOURCE, DI_K10),
    series!(Material::CastIron, "ISO 13", "class A", CI_SOURCE, CI_A),
    series!(Material::CastIron, "ISO 13", "class B", CI_SOURCE, CI_B),
    series!(Material::Steel, "EN 10224", "L235", ST_SOURCE, ST),
    series!(
        Material::AsbestosCement,
        "ISO 160",
        "class 10",
        AC_SOURCE,
        AC10
    ),
    series!(
        Material::AsbestosCement,
        "ISO 160",
        "class 15",
        AC_SOURCE,
        AC15
    ),
    series!(
        Material::AsbestosCement,
        "ISO 160",
        "class 20",
        AC_SOURCE,
        AC20
    ),
    series!(
        Material::AsbestosCement,
        "ISO 160",
        "class 25",
        AC_SOURCE,
        AC25
    ),
];

/// Every catalogue size of `material`, with its series.
pub fn sizes_of(material: Material) -> impl Iterator<Item = (&'static Series, Size)> {
    CATALOGUE
        .iter()
        .filter(move |s| s.material == material)
        .flat_map(|s| s.sizes.iter().map(move |z| (s, *z)))
}

/// The series a record (material, OD, wall in mm) belongs to, if it is a catalogue size
/// (within 0.5 mm in OD and 0.05 mm in wall).
pub fn series_of(material: Material, od_mm: f64, wall_mm: f64) -> Option<&'static Series> {
    sizes_of(material)
        .find(|(_, z)| (z.od_mm - od_mm).abs() <= 0.5 && (z.wall_mm - wall_mm).abs() <= 0.05)
        .map(|(s, _)| s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(m: Material, class: &str, od: f64) -> f64 {
        CATALOGUE
            .iter()
            .find(|s| s.material == m && s.class == class)
            .and_then(|s| s.sizes.iter().find(|z| z.od_mm == od))
            .map(|z| z.wall_mm)
            .unwrap_or(f64::NAN)
    }

    #[test]
    fn catalogue_spot_checks_against_the_standards() {
        // ISO 4427-2 Table 2: 180 SDR 11 16.4, SDR 17 10.7; 90 SDR 17 5.4 (not 90/17 = 5.3:
        // the ISO 4065 series use the exact R10 numbers); 250 SDR 26 9.6.
        assert_eq!(wall(Material::Hdpe, "SDR 11", 180.0), 16.4);
        assert_eq!(wall(Material::Hdpe, "SDR 17", 180.0), 10.7);
        assert_eq!(wall(Material::Mdpe, "SDR 17", 90.0), 5.4);
        assert_eq!(wall(Material::Mdpe, "SDR 26", 250.0), 9.6);
        // EN 1452-2: 110 SDR 21 5.3, 160 SDR 41 4.0, 315 SDR 33 9.7, 160 SDR 17 9.5.
        assert_eq!(wall(Material::Pvc, "SDR 21", 110.0), 5.3);
        assert_eq!(wall(Material::Pvc, "SDR 41", 160.0), 4.0);
        assert_eq!(wall(Material::Pvc, "SDR 33", 315.0), 9.7);
        assert_eq!(wall(Material::Pvc, "SDR 17", 160.0), 9.5);
        // ISO 2531: DN150 K9 = 9 x 0.65 = 5.85 -> the 6 mm minimum; DN300 K9 7.2, K10 8.0;
        // DN400 K7 5.6 -> 7 x 0.9 = 6.3.
        assert_eq!(wall(Material::DuctileIron, "K9", 170.0), 6.0);
        assert_eq!(wall(Material::DuctileIron, "K9", 326.0), 7.2);
        assert_eq!(wall(Material::DuctileIron, "K10", 326.0), 8.0);
        assert_eq!(wall(Material::DuctileIron, "K7", 429.0), 6.3);
        // ISO 13: DN150 class A 10.0, class B 11.0; DN300 class B 14.3.
        assert_eq!(wall(Material::CastIron, "class A", 170.0), 10.0);
        assert_eq!(wall(Material::CastIron, "class B", 170.0), 11.0);
        assert_eq!(wall(Material::CastIron, "class B", 326.0), 14.3);
        // EN 10224: 168.3 x 5.6.
        assert!(sizes_of(Material::Steel).any(|(_, z)| z.od_mm == 168.3 && z.wall_mm == 5.6));
        // Every plastic series covers 63-400 mm, every wall is positive and thinner than OD/4.
        for se in &CATALOGUE {
            for z in se.sizes {
                assert!(z.wall_mm > 0.0 && z.wall_mm < z.od_mm / 4.0, "{se:?} {z:?}");
                if se.material.is_plastic() {
                    let sdr: f64 = se.class[4..].parse().unwrap();
                    // ISO 4065 computes the wall from the exact R10 series (SDR 17 is
                    // 16.89), within 1 %, then rounds to 0.1 mm.
                    let tol = 0.1 + 0.01 * z.wall_mm;
                    assert!((z.wall_mm - z.od_mm / sdr).abs() <= tol, "{se:?} {z:?}");
                }
            }
        }
        assert_eq!(
            series_of(Material::Hdpe, 180.0, 10.7).map(|s| s.class),
            Some("SDR 17")
        );
        assert!(series_of(Material::Hdpe, 180.0, 10.0).is_none());
    }
}
