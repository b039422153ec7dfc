//! Value storage: the per-grid compression (none, zip, blosc), OpenVDB's active-mask compression
//! of node values, and value decoding (float, double, half).
//!
//! Every buffer is allocated at the size the *tree* dictates (a node holds a fixed number of
//! values), never at a size the file declares, so hostile sizes cannot cause a large allocation.

use super::bytes::Cursor;
use crate::error::Result;
use std::borrow::Cow;

/// Per-grid compression flags.
pub(crate) const COMPRESS_ZIP: u32 = 0x1;
pub(crate) const COMPRESS_ACTIVE_MASK: u32 = 0x2;
pub(crate) const COMPRESS_BLOSC: u32 = 0x4;

/// A tree's value type.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ValueType {
    /// The token in the tree type name: `float`, `double`, `vec3s`, …
    pub token: String,
    /// Bytes of one value at full precision.
    pub size: usize,
    /// Number of components (1 for scalars).
    pub comps: usize,
    /// Floating point (stored as half when the grid says so).
    pub real: bool,
}

impl ValueType {
    /// The value type of a tree token, or None for types with another leaf layout (bool, mask,
    /// points, strings).
    pub fn from_token(t: &str) -> Option<ValueType> {
        let (size, comps, real) = match t {
            "float" => (4, 1, true),
            "double" => (8, 1, true),
            "half" => (2, 1, true),
            "int32" | "uint32" => (4, 1, false),
            "int64" => (8, 1, false),
            "vec3s" => (12, 3, true),
            "vec3d" => (24, 3, true),
            "vec3i" => (12, 3, false),
            _ => return None,
        };
        Some(ValueType {
            token: t.to_string(),
            size,
            comps,
            real,
        })
    }

    /// True for the scalar types (`info` sums them).
    pub fn is_scalar(&self) -> bool {
        self.comps == 1
    }

    /// True for the types a density is read from: real scalars (float, double, half).
    pub fn is_density(&self) -> bool {
        self.comps == 1 && self.real
    }

    /// Bytes of one stored value (half precision when `half`).
    pub fn stored_size(&self, half: bool) -> usize {
        if half && self.real && self.token != "half" {
            2 * self.comps
        } else {
            self.size
        }
    }

    /// Decode a stored scalar (first component for vectors; only scalars are ever summed).
    pub fn decode(&self, b: &[u8], half: bool) -> f64 {
        if half && self.real || self.token == "half" {
            return half_to_f32(u16::from_le_bytes([b[0], b[1]])) as f64;
        }
        match self.token.as_str() {
            "float" | "vec3s" => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            "double" | "vec3d" => f64::from_le_bytes(b[..8].try_into().expect("8 bytes")),
            "int32" | "vec3i" => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            "uint32" => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            "int64" => i64::from_le_bytes(b[..8].try_into().expect("8 bytes")) as f64,
            _ => 0.0,
        }
    }
}

/// IEEE 754 binary16 → f32, exact (including subnormals, infinities and NaN).
pub fn half_to_f32(h: u16) -> f32 {
    let sign = ((h >> 15) as u32) << 31;
    let exp = ((h >> 10) & 0x1f) as u32;
    let man = (h & 0x3ff) as u32;
    let bits = match exp {
        0 if man == 0 => sign,
        0 => {
            // Subnormal: value = man × 2⁻²⁴.
            let v = man as f32 * (1.0 / 16_777_216.0);
            return if sign != 0 { -v } else { v };
        }
        0x1f => sign | 0x7f80_0000 | (man << 13),
        _ => sign | ((exp + 112) << 23) | (man << 13),
    };
    f32::from_bits(bits)
}

/// Read `n` bytes of node data under `compression` (OpenVDB's `readData`).
pub(crate) fn read_data<'a>(c: &mut Cursor<'a>, n: usize, compression: u32, what: &str) -> Result<Cow<'a, [u8]>> {
    if compression & (COMPRESS_BLOSC | COMPRESS_ZIP) == 0 {
        return Ok(Cow::Borrowed(c.take(n, what)?));
    }
    let codec = if compression & COMPRESS_BLOSC != 0 { "blosc" } else { "zip" };
    let declared = c.i64("compressed chunk size")?;
    if declared <= 0 {
        // Stored uncompressed: −size bytes follow.
        let raw = declared.unsigned_abs();
        if raw != n as u64 {
            return Err(c.err(format!(
                "corrupt {what}: an uncompressed chunk of {raw} bytes where the tree needs {n}"
            )));
        }
        return Ok(Cow::Borrowed(c.take(n, what)?));
    }
    let len = usize::try_from(declared).unwrap_or(usize::MAX);
    let start = c.pos();
    let src = c.take(len, what)?;
    let out = if codec == "blosc" {
        blosc_decompress(src, n)
    } else {
        zlib_decompress(src, n)
    };
    out.map(Cow::Owned)
        .map_err(|m| crate::error::Error::format(c.file(), format!("corrupt {codec} chunk of {what} at byte offset {start}: {m}")))
}

/// Inflate a zlib stream into exactly `n` bytes.
pub(crate) fn zlib_decompress(src: &[u8], n: usize) -> std::result::Result<Vec<u8>, String> {
    let mut out = vec![0u8; n];
    let mut d = flate2::Decompress::new(true);
    let status = d
        .decompress(src, &mut out, flate2::FlushDecompress::Finish)
        .map_err(|e| format!("zlib: {e}"))?;
    if status != flate2::Status::StreamEnd || d.total_out() != n as u64 {
        return Err(format!(
            "zlib stream gave {} bytes{}, the tree needs exactly {n}",
            d.total_out(),
            if status == flate2::Status::StreamEnd {
                ""
            } else {
                " without ending"
            }
        ));
    }
    Ok(out)
}

/// Decompress a Blosc 1 chunk (as OpenVDB writes it: LZ4 with byte shuffle; zlib also accepted)
/// into exactly `n` bytes. Header: version, compressor version, flags, type size, then u32
/// uncompressed size, block size and compressed size; then block offsets and blocks.
pub(crate) fn blosc_decompress(src: &[u8], n: usize) -> std::result::Result<Vec<u8>, String> {
    if src.len() < 16 {
        return Err(format!("{} bytes, shorter than the 16-byte blosc header", src.len()));
    }
    let u32_at = |o: usize| u32::from_le_bytes([src[o], src[o + 1], src[o + 2], src[o + 3]]) as usize;
    let (flags, typesize) = (src[2], src[3] as usize);
    let (nbytes, blocksize, cbytes) = (u32_at(4), u32_at(8), u32_at(12));
    if nbytes != n {
        return Err(format!("blosc header says {nbytes} bytes uncompressed, the tree needs {n}"));
    }
    if cbytes > src.len() || cbytes < 16 {
        return Err(format!("blosc header says {cbytes} compressed bytes, the chunk has {}", src.len()));
    }
    let src = &src[..cbytes];
    if flags & 0x2 != 0 {
        // Stored without compression.
        return src
            .get(16..16 + n)
            .map(<[u8]>::to_vec)
            .ok_or_else(|| format!("uncompressed blosc chunk holds {} bytes, not {n}", src.len() - 16));
    }
    if n == 0 {
        return Ok(Vec::new());
    }
    if blocksize == 0 || typesize == 0 {
        return Err(format!("blosc block size {blocksize}, type size {typesize}: must be positive"));
    }
    if flags & 0x4 != 0 {
        return Err("bit-shuffled blosc data is not supported (OpenVDB writes byte-shuffled)".into());
    }
    let format = flags >> 5;
    if format != 1 && format != 3 {
        let name = ["blosclz", "lz4", "snappy", "zlib", "zstd"]
            .get(format as usize)
            .copied()
            .unwrap_or("unknown");
        return Err(format!(
            "blosc compressor `{name}` is not supported (OpenVDB writes lz4; zlib is also read)"
        ));
    }
    let shuffle = flags & 0x1 != 0 && typesize > 1;
    let dont_split = flags & 0x10 != 0;
    let nblocks = n.div_ceil(blocksize);
    let leftover = n % blocksize;
    if 16 + 4 * nblocks > src.len() {
        return Err(format!("{nblocks} blosc blocks declared, the chunk cannot hold their offsets"));
    }
    let mut out = vec![0u8; n];
    let mut tmp = vec![0u8; if shuffle { blocksize.min(n) } else { 0 }];
    for j in 0..nblocks {
        let start = u32_at(16 + 4 * j);
        let is_leftover = j == nblocks - 1 && leftover != 0;
        let bsize = if is_leftover { leftover } else { blocksize };
        let dest = &mut out[j * blocksize..j * blocksize + bsize];
        let nsplits = if !dont_split && typesize <= 16 && bsize / typesize >= 128 && !is_leftover {
            typesize
        } else {
            1
        };
        let neblock = bsize / nsplits;
        let target: &mut [u8] = if shuffle { &mut tmp[..bsize] } else { dest };
        let mut pos = start;
        for s in 0..nsplits {
            let hdr = src
                .get(pos..pos + 4)
                .ok_or_else(|| format!("blosc block {j} starts at {pos}, past the chunk end"))?;
            let cb = i32::from_le_bytes([hdr[0], hdr[1], hdr[2], hdr[3]]);
            pos += 4;
            let cb = usize::try_from(cb).map_err(|_| format!("blosc block {j} has negative size {cb}"))?;
            let part = src
                .get(pos..pos.saturating_add(cb))
                .ok_or_else(|| format!("blosc block {j} declares {cb} bytes past the chunk end"))?;
            let t = &mut target[s * neblock..(s + 1) * neblock];
            if cb == neblock {
                t.copy_from_slice(part);
            } else if format == 1 {
                let got = lz4_flex::block::decompress_into(part, t).map_err(|e| format!("lz4 block {j}: {e}"))?;
                if got != neblock {
                    return Err(format!("lz4 block {j} gave {got} bytes, expected {neblock}"));
                }
            } else {
                let v = zlib_decompress(part, neblock).map_err(|e| format!("block {j}: {e}"))?;
                t.copy_from_slice(&v);
            }
            pos += cb;
        }
        if shuffle {
            // Byte unshuffle: stream b holds byte b of every element.
            let ne = bsize / typesize;
            for i in 0..ne {
                for b in 0..typesize {
                    dest[i * typesize + b] = tmp[b * ne + i];
                }
            }
            let rem = bsize - ne * typesize;
            dest[bsize - rem..].copy_from_slice(&tmp[bsize - rem..bsize]);
        }
    }
    Ok(out)
}

/// Read one node's values (OpenVDB's `readCompressedValues`) and return the values of its
/// active entries (set bits of `value_mask`, in offset order), decoded as scalars; for vector
/// types the values are skipped and an empty vector returned.
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_node_values(
    c: &mut Cursor,
    value_mask: &[u64],
    node_size: usize,
    vt: &ValueType,
    half: bool,
    compression: u32,
    what: &str,
) -> Result<Vec<f64>> {
    let meta = c.u8("node compression byte")?;
    if meta > 6 {
        return Err(c.err(format!("corrupt {what}: compression metadata byte is {meta}, must be 0 to 6")));
    }
    if matches!(meta, 2 | 4 | 5) {
        c.skip(vt.size, "inactive value")?;
        if meta == 5 {
            c.skip(vt.size, "inactive value")?;
        }
    }
    if matches!(meta, 3..=5) {
        c.skip(node_size / 8, "selection mask")?;
    }
    let active = value_mask.iter().map(|w| w.count_ones() as usize).sum::<usize>();
    let mask_compressed = compression & COMPRESS_ACTIVE_MASK != 0 && meta != 6;
    let count = if mask_compressed { active } else { node_size };
    let elem = vt.stored_size(half);
    // A half grid writes nothing at all for an empty buffer (not even a chunk size).
    if count == 0 && half && vt.real {
        return Ok(Vec::new());
    }
    let data = read_data(c, count * elem, compression, what)?;
    if !vt.is_scalar() {
        return Ok(Vec::new());
    }
    let mut out = Vec::with_capacity(active);
    if count == active {
        out.extend(data.chunks_exact(elem).map(|b| vt.decode(b, half)));
    } else {
        for (w, &word) in value_mask.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let i = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                out.push(vt.decode(&data[i * elem..(i + 1) * elem], half));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_conversion_exact_cases() {
        assert_eq!(half_to_f32(0x3c00), 1.0);
        assert_eq!(half_to_f32(0xc000), -2.0);
        assert_eq!(half_to_f32(0x7bff), 65504.0);
        assert_eq!(half_to_f32(0x0001), 2f32.powi(-24));
        assert_eq!(half_to_f32(0x0400), 2f32.powi(-14));
        assert_eq!(half_to_f32(0x3555), 0.333_251_95);
        assert!(half_to_f32(0x7c00).is_infinite());
        assert!(half_to_f32(0x7e00).is_nan());
        assert_eq!(half_to_f32(0x8000).to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn blosc_memcpy_and_bad_headers() {
        let payload: Vec<u8> = (0..40u8).collect();
        let mut b = vec![2, 1, 0x2, 4];
        for v in [40u32, 40, 56] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&payload);
        assert_eq!(blosc_decompress(&b, 40).unwrap(), payload);
        assert!(blosc_decompress(&b, 41).is_err());
        assert!(blosc_decompress(&b[..20], 40).is_err());
    }

    /// Build a blosc chunk the way blosc 1 lays it out: header, block offsets, per block
    /// `nsplits` streams of (i32 size, LZ4 block), byte-shuffled.
    fn blosc_chunk(data: &[u8], typesize: usize, blocksize: usize, split: bool) -> Vec<u8> {
        let n = data.len();
        let nblocks = n.div_ceil(blocksize);
        let mut body = Vec::new();
        let mut starts = Vec::new();
        for j in 0..nblocks {
            let block = &data[j * blocksize..((j + 1) * blocksize).min(n)];
            let leftover = block.len() < blocksize;
            // Shuffle: stream b holds byte b of every element; the tail bytes stay in place.
            let ne = block.len() / typesize;
            let mut sh = block.to_vec();
            for i in 0..ne {
                for b in 0..typesize {
                    sh[b * ne + i] = block[i * typesize + b];
                }
            }
            starts.push(16 + 4 * nblocks + body.len());
            let nsplits = if split && !leftover && block.len() / typesize >= 128 {
                typesize
            } else {
                1
            };
            let ne = block.len() / nsplits;
            for s in 0..nsplits {
                let c = lz4_flex::block::compress(&sh[s * ne..(s + 1) * ne]);
                body.extend_from_slice(&(c.len() as i32).to_le_bytes());
                body.extend_from_slice(&c);
            }
        }
        let mut out = vec![2, 1, 0x1 | (1 << 5) | if split { 0 } else { 0x10 }, typesize as u8];
        let total = 16 + 4 * nblocks + body.len();
        for v in [n, blocksize, total] {
            out.extend_from_slice(&(v as u32).to_le_bytes());
        }
        for st in starts {
            out.extend_from_slice(&(st as u32).to_le_bytes());
        }
        out.extend_from_slice(&body);
        out
    }

    #[test]
    fn blosc_lz4_shuffled_split_unsplit_and_leftover_blocks() {
        let data: Vec<u8> = (0..2050u32)
            .flat_map(|i| ((i as f32 * 0.01).sin()).to_le_bytes())
            .take(8202)
            .collect();
        for (blocksize, split) in [(8202, false), (2048, true), (2048, false), (4096, true)] {
            let c = blosc_chunk(&data, 4, blocksize, split);
            assert_eq!(
                blosc_decompress(&c, data.len()).unwrap(),
                data,
                "blocksize {blocksize} split {split}"
            );
            // Corrupt every byte of the chunk in turn: errors or wrong data, never a panic.
            for i in (0..c.len()).step_by(7) {
                let mut bad = c.clone();
                bad[i] ^= 0x5a;
                let _ = blosc_decompress(&bad, data.len());
            }
        }
    }
}
