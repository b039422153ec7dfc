//! A bounds-checked little-endian byte cursor. Every read names what it was reading, so a
//! truncated or corrupt file gives an error with the offset and the structure at fault.

use crate::error::{Error, Result};

/// Reads little-endian values from a byte slice, never past its end.
pub(crate) struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
    file: &'a str,
}

impl<'a> Cursor<'a> {
    /// A cursor at offset 0 of `buf`; `file` names the source in errors.
    pub fn new(buf: &'a [u8], file: &'a str) -> Self {
        Cursor { buf, pos: 0, file }
    }

    /// Current offset.
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// Bytes left after the cursor.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    /// The file label.
    pub fn file(&self) -> &'a str {
        self.file
    }

    /// A format error naming the file and the current offset.
    pub fn err(&self, message: impl std::fmt::Display) -> Error {
        Error::format(self.file, format!("{message} (at byte offset {})", self.pos))
    }

    /// Move to absolute offset `pos` (must be inside the file).
    pub fn seek(&mut self, pos: u64, what: &str) -> Result<()> {
        match usize::try_from(pos) {
            Ok(p) if p <= self.buf.len() => {
                self.pos = p;
                Ok(())
            }
            _ => Err(self.err(format!(
                "corrupt file: {what} points to byte {pos}, past the end of the {}-byte file",
                self.buf.len()
            ))),
        }
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(format!(
                "truncated file: reading {what} needs {n} bytes but only {} remain",
                self.remaining()
            )));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    /// Skip `n` bytes.
    pub fn skip(&mut self, n: usize, what: &str) -> Result<()> {
        self.take(n, what).map(|_| ())
    }

    fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    pub fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.arr::<1>(what)?[0])
    }
    pub fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    pub fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.arr(what)?))
    }
    pub fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.arr(what)?))
    }
    pub fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.arr(what)?))
    }
    pub fn vec3d(&mut self, what: &str) -> Result<[f64; 3]> {
        Ok([self.f64(what)?, self.f64(what)?, self.f64(what)?])
    }
    pub fn vec3i(&mut self, what: &str) -> Result<[i32; 3]> {
        Ok([self.i32(what)?, self.i32(what)?, self.i32(what)?])
    }

    /// An OpenVDB string: u32 length, then that many bytes (lossy UTF-8).
    pub fn string(&mut self, what: &str) -> Result<String> {
        let n = self.u32(what)? as usize;
        let b = self.take(n, what)?;
        Ok(String::from_utf8_lossy(b).into_owned())
    }
}
