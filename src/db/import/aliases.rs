//! The material spellings of utility inventories and GIS layers, mapped to pipewave's codes
//! (docs/interface.md: `Cast Iron`, `Ductile Iron`, `DICL`, `Steel`, `uPVC`, `PVC-U`, `PE80`,
//! `PE100`, `MDPE`, `HDPE`, `Asbestos Cement`, ...). The one table of them: every importer (CSV
//! and GIS layers) reads materials through [`material`].

use crate::physics::{InputError, Material};

/// Spellings, compared after `normalise` (lower case, no spaces, hyphens, underscores or
/// dots), and the material each one means. The codes themselves (`CI`, `DI`, ...) are read by
/// `Material::from_str`.
///
/// - Grey cast iron: "Cast Iron", "Grey/Gray Cast Iron", "Grey Iron", "GCI", "Pit Cast Iron",
///   "Spun Iron" (spun grey iron).
/// - Ductile iron: "Ductile Iron", "DICL" (ductile iron, cement lined), "DIP" (ductile iron pipe).
/// - Steel: "Steel", "STL", "Mild Steel", "MSCL" (mild steel, cement lined), "Welded Steel".
/// - Unplasticised PVC: "uPVC", "PVC-U", "U-PVC", "Polyvinyl Chloride".
/// - PE80 is the medium-density grade and PE100 the high-density one (EN 12201 / ISO 4427
///   material designations), so they map to MDPE and HDPE.
/// - Asbestos cement: "Asbestos Cement", "ACP" (asbestos cement pipe), "Fibro Cement".
pub const MATERIAL_ALIASES: &[(&str, Material)] = &[
    ("castiron", Material::CastIron),
    ("greycastiron", Material::CastIron),
    ("graycastiron", Material::CastIron),
    ("greyiron", Material::CastIron),
    ("grayiron", Material::CastIron),
    ("gci", Material::CastIron),
    ("pitcastiron", Material::CastIron),
    ("spuniron", Material::CastIron),
    ("ductileiron", Material::DuctileIron),
    ("dicl", Material::DuctileIron),
    ("dip", Material::DuctileIron),
    ("steel", Material::Steel),
    ("stl", Material::Steel),
    ("mildsteel", Material::Steel),
    ("mscl", Material::Steel),
    ("weldedsteel", Material::Steel),
    ("upvc", Material::Pvc),
    ("pvcu", Material::Pvc),
    ("polyvinylchloride", Material::Pvc),
    ("pe80", Material::Mdpe),
    ("pe100", Material::Hdpe),
    ("asbestoscement", Material::AsbestosCement),
    ("acp", Material::AsbestosCement),
    ("fibrocement", Material::AsbestosCement),
];

/// Lower case without spaces, hyphens, underscores or dots: `PVC-U`, `pvc u` and `PVC_U` agree.
fn normalise(s: &str) -> String {
    s.chars()
        .filter(|c| !matches!(c, ' ' | '-' | '_' | '.'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// The material of an inventory cell: a pipewave code (case-insensitive) or a spelling of
/// [`MATERIAL_ALIASES`]. The error is the one of `Material::from_str`, listing the codes.
pub fn material(text: &str) -> Result<Material, InputError> {
    let key = normalise(text);
    if let Some(&(_, m)) = MATERIAL_ALIASES.iter().find(|(a, _)| *a == key) {
        return Ok(m);
    }
    key.parse::<Material>().map_err(|_| InputError::Unknown {
        what: "material",
        value: text.to_string(),
        expected: "CI, DI, ST, PVC, MDPE, HDPE, AC",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spellings_of_the_interface_contract_are_understood() {
        for (s, m) in [
            ("Cast Iron", Material::CastIron),
            ("CAST IRON", Material::CastIron),
            ("Ductile Iron", Material::DuctileIron),
            ("DICL", Material::DuctileIron),
            ("Steel", Material::Steel),
            ("uPVC", Material::Pvc),
            ("PVC-U", Material::Pvc),
            ("pvc", Material::Pvc),
            ("PE80", Material::Mdpe),
            ("PE 100", Material::Hdpe),
            ("mdpe", Material::Mdpe),
            ("HDPE", Material::Hdpe),
            ("Asbestos Cement", Material::AsbestosCement),
            ("ac", Material::AsbestosCement),
            ("ci", Material::CastIron),
        ] {
            assert_eq!(material(s).unwrap(), m, "{s}");
        }
        let e = material("Brass").unwrap_err().to_string();
        assert_eq!(
            e,
            "unknown material 'Brass' (expected one of CI, DI, ST, PVC, MDPE, HDPE, AC)"
        );
    }

    #[test]
    fn every_alias_is_normalised_and_unique() {
        let mut keys: Vec<&str> = MATERIAL_ALIASES.iter().map(|(a, _)| *a).collect();
        for k in &keys {
            assert_eq!(normalise(k), *k);
        }
        keys.sort_unstable();
        let n = keys.len();
        keys.dedup();
        assert_eq!(keys.len(), n);
    }
}
