//! Frame patterns in file names: `cloud.####.vdb`, `cloud.$F4.vdb`, `cloud.%04d.vdb`.
//!
//! A pattern holds exactly one frame token; the frame number replaces it, zero-padded to the
//! token's width (wider numbers are written in full):
//! - a run of `#`: one digit per `#` (`####` = 4), except a lone `#`, which means 4 digits (the
//!   RV/Katana convention, so `cloud.#.vdb` and `cloud.####.vdb` name the same files);
//! - a run of `@`: one digit per `@` (`@` = unpadded);
//! - `$F` (unpadded) or `$F` followed by one digit N (`$F4`): Houdini;
//! - `%d` or `%0Nd` (`%04d`): printf.

use crate::error::{Error, Result};

/// A file name with one frame token.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePattern {
    before: String,
    after: String,
    width: usize,
}

/// One token found in a name: where it starts and ends (bytes) and its digit count.
struct Token {
    start: usize,
    end: usize,
    width: usize,
}

/// What is wrong with a name that looks like a pattern and is not one.
type Malformed = String;

impl FramePattern {
    /// The pattern in `name`: None when it has no frame token, an error naming `field` in
    /// `file` when it has a malformed or more than one token.
    pub fn parse(name: &str, file: &str, field: &str) -> Result<Option<FramePattern>> {
        let tokens = tokens(name).map_err(|m| bad(file, field, name, &m))?;
        match tokens.as_slice() {
            [] => Ok(None),
            [t] => Ok(Some(FramePattern {
                before: name[..t.start].to_string(),
                after: name[t.end..].to_string(),
                width: t.width,
            })),
            _ => Err(bad(file, field, name, "it has more than one frame token; use exactly one")),
        }
    }

    /// The file name of `frame`.
    pub fn name(&self, frame: u32) -> String {
        format!("{}{:0w$}{}", self.before, frame, self.after, w = self.width)
    }
}

fn bad(file: &str, field: &str, name: &str, why: &str) -> Error {
    Error::invalid(
        file,
        field,
        format!("`{name}` is not a frame pattern: {why} (write the frame as `####` = 4 digits, `@` = 1 digit, `$F4` or `%04d`)"),
    )
}

/// Every frame token of `name`, in order.
fn tokens(name: &str) -> std::result::Result<Vec<Token>, Malformed> {
    let b = name.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let start = i;
        match b[i] {
            c @ (b'#' | b'@') => {
                while i < b.len() && b[i] == c {
                    i += 1;
                }
                if i < b.len() && matches!(b[i], b'#' | b'@') {
                    return Err("it mixes `#` and `@` in one token".into());
                }
                let n = i - start;
                let width = if c == b'#' && n == 1 { 4 } else { n };
                out.push(Token { start, end: i, width });
            }
            b'$' if b.get(i + 1) == Some(&b'F') => {
                i += 2;
                let mut width = 1;
                if let Some(d) = b.get(i).filter(|d| d.is_ascii_digit()) {
                    width = usize::from(d - b'0').max(1);
                    i += 1;
                }
                out.push(Token { start, end: i, width });
            }
            b'%' => {
                i += 1;
                let digits = b[i..].iter().take_while(|d| d.is_ascii_digit()).count();
                let spec = &name[i..i + digits];
                i += digits;
                if b.get(i) != Some(&b'd') {
                    return Err("`%` must be followed by `d` or `0Nd` (e.g. `%04d`)".into());
                }
                i += 1;
                let width = match spec {
                    "" => 1,
                    s if s.starts_with('0') && s.len() > 1 => s[1..].parse::<usize>().map_err(|e| e.to_string())?,
                    _ => return Err("the printf width must be zero-padded, `%0Nd` (e.g. `%04d`)".into()),
                };
                if !(1..=9).contains(&width) {
                    return Err("the printf width must be 1 to 9 digits".into());
                }
                out.push(Token { start, end: i, width });
            }
            _ => i += 1,
        }
    }
    if out.iter().any(|t| t.width > 9) {
        return Err("a frame token is at most 9 digits wide".into());
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name(p: &str, f: u32) -> String {
        FramePattern::parse(p, "s.toml", "medium.grid").unwrap().unwrap().name(f)
    }

    #[test]
    fn every_spelling_names_the_same_files() {
        for p in ["cloud.####.vdb", "cloud.#.vdb", "cloud.$F4.vdb", "cloud.%04d.vdb", "cloud.@@@@.vdb"] {
            assert_eq!(name(p, 7), "cloud.0007.vdb", "{p}");
            assert_eq!(name(p, 12345), "cloud.12345.vdb", "{p}");
        }
        assert_eq!(name("f/c.@.npy", 7), "f/c.7.npy");
        assert_eq!(name("c.$F.raw", 42), "c.42.raw");
        assert_eq!(name("c_%d.vol", 3), "c_3.vol");
        assert_eq!(name("##/c.vdb", 3), "03/c.vdb");
    }

    #[test]
    fn plain_names_and_bad_patterns() {
        assert_eq!(FramePattern::parse("cloud.vdb", "f", "k").unwrap(), None);
        assert_eq!(FramePattern::parse("cost$5.vdb", "f", "k").unwrap(), None);
        for bad in [
            "a.####.####.vdb",
            "a.#@.vdb",
            "a.%4d.vdb",
            "a.%s.vdb",
            "a.%0d.vdb",
            "a.$F4.%04d.vdb",
            "a.##########.vdb",
        ] {
            let e = FramePattern::parse(bad, "s.toml", "medium.grid").unwrap_err().to_string();
            assert!(e.contains("medium.grid") && e.contains("not a frame pattern"), "{bad}: {e}");
        }
    }
}
