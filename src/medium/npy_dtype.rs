//! The element types a `.npy` density array may hold (its header's `descr`): floats of 2, 4 or 8
//! bytes, unsigned and signed integers of 1 to 8 bytes, and booleans, in either byte order. Each
//! value is read as the number it holds (an integer 0–255 is a density 0–255, a boolean 0 or 1;
//! `medium.sigma_t` is the extinction at density 1), the same as a `.raw` of uint8 or uint16.

use crate::medium::vdb::codec::half_to_f32;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Float,
    Unsigned,
    Signed,
    Bool,
}

/// A `.npy` element type the density can be read from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NpyDtype {
    kind: Kind,
    /// Bytes per value.
    pub size: usize,
    big_endian: bool,
}

/// What a refusal of an unknown `descr` suggests.
pub const SUPPORTED: &str = "float16/32/64 ('<f4' is float32), (u)int8 to (u)int64 or bool";

impl NpyDtype {
    /// Parse a NumPy `descr` such as `<f4`, `>f8`, `|u1`, `<i2` or `|b1`; `None` for any other
    /// (complex, strings, records, datetimes).
    pub fn parse(descr: &str) -> Option<NpyDtype> {
        let mut chars = descr.chars();
        // '=' is native order; NumPy writes '<' or '>' instead, but a hand-made header may not.
        let big_endian = match chars.next()? {
            '<' | '|' | '=' => false,
            '>' => true,
            _ => return None,
        };
        let kind = match chars.next()? {
            'f' => Kind::Float,
            'u' => Kind::Unsigned,
            'i' => Kind::Signed,
            'b' => Kind::Bool,
            _ => return None,
        };
        let size: usize = chars.as_str().parse().ok()?;
        let valid = match kind {
            Kind::Float => matches!(size, 2 | 4 | 8),
            Kind::Unsigned | Kind::Signed => matches!(size, 1 | 2 | 4 | 8),
            Kind::Bool => size == 1,
        };
        valid.then_some(NpyDtype { kind, size, big_endian })
    }

    /// The value of one element (`bytes.len() == self.size`), in f64 (exact for every type but
    /// 64-bit integers beyond 2⁵³, which round).
    pub fn value(&self, bytes: &[u8]) -> f64 {
        let mut b = [0u8; 8];
        b[..self.size].copy_from_slice(bytes);
        if self.big_endian {
            b[..self.size].reverse();
        }
        let unsigned = u64::from_le_bytes(b);
        match self.kind {
            Kind::Bool => (unsigned != 0) as u8 as f64,
            Kind::Unsigned => unsigned as f64,
            Kind::Signed => {
                // Sign-extend from `size` bytes.
                let shift = 64 - 8 * self.size as u32;
                ((unsigned << shift) as i64 >> shift) as f64
            }
            Kind::Float => match self.size {
                2 => half_to_f32(unsigned as u16) as f64,
                4 => f32::from_bits(unsigned as u32) as f64,
                _ => f64::from_bits(unsigned),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_supported_descr_reads_its_values() {
        let cases: [(&str, Vec<u8>, f64); 12] = [
            ("<f4", 1.5f32.to_le_bytes().to_vec(), 1.5),
            (">f4", 1.5f32.to_be_bytes().to_vec(), 1.5),
            ("<f8", 0.25f64.to_le_bytes().to_vec(), 0.25),
            (">f8", 0.25f64.to_be_bytes().to_vec(), 0.25),
            ("<f2", 0x3e00u16.to_le_bytes().to_vec(), 1.5),
            ("|u1", vec![200], 200.0),
            (">u2", 1000u16.to_be_bytes().to_vec(), 1000.0),
            ("<u8", 7u64.to_le_bytes().to_vec(), 7.0),
            ("|i1", vec![0xff], -1.0),
            ("<i2", (-300i16).to_le_bytes().to_vec(), -300.0),
            (">i4", (-5i32).to_be_bytes().to_vec(), -5.0),
            ("|b1", vec![1], 1.0),
        ];
        for (descr, bytes, want) in cases {
            let t = NpyDtype::parse(descr).unwrap_or_else(|| panic!("{descr} refused"));
            assert_eq!(t.size, bytes.len(), "{descr}");
            assert_eq!(t.value(&bytes), want, "{descr}");
        }
    }

    #[test]
    fn other_descrs_are_refused() {
        for d in ["<c8", "<f16", "|b2", "<u3", "|S4", "<M8", "f4", "<", "", "<f"] {
            assert_eq!(NpyDtype::parse(d), None, "{d}");
        }
    }
}
