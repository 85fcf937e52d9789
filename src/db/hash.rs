//! FNV-1a 64-bit hashing of canonical text, for `inputs_hash` and `settings_hash`.
//!
//! We write it ourselves rather than use `std`'s `DefaultHasher`, whose output may change between
//! Rust releases: these hashes are stored in the database and compared across program versions.
//! FNV-1a is not cryptographic; it only detects changed inputs.
//! Reference: Fowler, Noll, Vo, "FNV hash", <http://www.isthe.com/chongo/tech/comp/fnv/>.

use std::fmt::Write as _;

/// FNV-1a 64-bit offset basis.
const FNV_OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
/// FNV-1a 64-bit prime, 2^40 + 2^8 + 0xb3.
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// FNV-1a 64 of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(FNV_OFFSET_BASIS, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(FNV_PRIME)
    })
}

/// The state to start an incremental FNV-1a 64 from ([`fnv1a64_update`]).
pub const FNV1A64_START: u64 = FNV_OFFSET_BASIS;

/// FNV-1a 64 continued over `bytes` from `state`: hashing a text in pieces this way gives the
/// same value as [`fnv1a64`] of the whole (the hash is a left fold over the bytes).
pub fn fnv1a64_update(state: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(state, |h, &b| (h ^ u64::from(b)).wrapping_mul(FNV_PRIME))
}

/// FNV-1a 64 of `text`, as 16 lower-case hex digits (the form stored in the database).
pub fn fnv1a64_hex(text: &str) -> String {
    format!("{:016x}", fnv1a64(text.as_bytes()))
}

/// Builder of an unambiguous canonical text, one `key=value` per line. Numbers are written with
/// full precision (the shortest text that reads back to the same `f64`), texts with their length
/// so no value can imitate a separator, and NULL as `-`.
#[derive(Debug, Default, Clone)]
pub struct Canonical {
    text: String,
}

impl Canonical {
    /// A canonical text starting with a version tag, so a future change of the form is explicit.
    pub fn new(tag: &str) -> Self {
        let mut c = Self::default();
        c.text(tag, Some(tag));
        c
    }

    /// A number; `-0.0` is written as `0`.
    pub fn num(&mut self, key: &str, value: Option<f64>) -> &mut Self {
        match value {
            // `{:e}` prints the shortest digits that round-trip, e.g. 1.5e3.
            Some(v) => {
                let v = if v == 0.0 { 0.0 } else { v };
                let _ = writeln!(self.text, "{key}=f:{v:e}");
            }
            None => {
                let _ = writeln!(self.text, "{key}=-");
            }
        }
        self
    }

    /// An integer.
    pub fn int(&mut self, key: &str, value: Option<i64>) -> &mut Self {
        match value {
            Some(v) => {
                let _ = writeln!(self.text, "{key}=i:{v}");
            }
            None => {
                let _ = writeln!(self.text, "{key}=-");
            }
        }
        self
    }

    /// A text, length-prefixed.
    pub fn text(&mut self, key: &str, value: Option<&str>) -> &mut Self {
        match value {
            Some(v) => {
                let _ = writeln!(self.text, "{key}=s{}:{v}", v.len());
            }
            None => {
                let _ = writeln!(self.text, "{key}=-");
            }
        }
        self
    }

    /// The canonical text so far.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// Its FNV-1a 64 hash as 16 hex digits.
    pub fn hash_hex(&self) -> String {
        fnv1a64_hex(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hashing in pieces from [`FNV1A64_START`] is the hash of the whole text (the field's
    /// fingerprint is taken so as its inputs stream past).
    #[test]
    fn fnv_in_pieces_is_the_hash_of_the_whole() {
        let whole = fnv1a64(b"field v2 a|b\nc|d\n");
        let pieces = [&b"field v2 "[..], b"a|b\n", b"c|d\n"]
            .iter()
            .fold(FNV1A64_START, |h, p| fnv1a64_update(h, p));
        assert_eq!(whole, pieces);
        assert_ne!(whole, fnv1a64(b"field v2 a|b\n"));
    }

    /// Test vectors from the FNV reference page (test_fnv.c, FNV-1a 64).
    #[test]
    fn fnv1a64_matches_reference_vectors() {
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x8594_4171_f739_67e8);
        assert_eq!(fnv1a64_hex("a"), "af63dc4c8601ec8c");
    }

    #[test]
    fn canonical_text_is_stable_and_full_precision() {
        let mut c = Canonical::new("t1");
        c.num("x", Some(0.1 + 0.2))
            .num("z", Some(-0.0))
            .num("n", None)
            .int("i", Some(-3))
            .text("s", Some("a=b\nc"));
        assert_eq!(
            c.as_str(),
            "t1=s2:t1\nx=f:3.0000000000000004e-1\nz=f:0e0\nn=-\ni=i:-3\ns=s5:a=b\nc\n"
        );
    }

    #[test]
    fn numbers_that_differ_in_the_last_bit_hash_differently() {
        let a = 0.3_f64;
        let b = f64::from_bits(a.to_bits() + 1);
        let h = |v| Canonical::new("t").num("x", Some(v)).hash_hex();
        assert_ne!(h(a), h(b));
        assert_eq!(h(a), h(0.3));
    }
}
