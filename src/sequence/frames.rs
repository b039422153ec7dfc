//! Frame lists in the usual render-farm grammar: `1-240`, `1-240x2` (every 2nd frame), `1,5,9-12`,
//! and the split of a list into contiguous chunks, one per farm task.

use crate::error::{Error, Result};

/// Frames in ascending order, each once.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameList(Vec<u32>);

/// Most frames one list may hold (a typo like `1-9999999999` is an error, not hours of work).
const MAX_FRAMES: usize = 1_000_000;

impl FrameList {
    /// Parse `text`; errors name `field` in `file` and say what is allowed.
    pub fn parse(text: &str, file: &str, field: &str) -> Result<FrameList> {
        let bad = |why: String| {
            Error::invalid(
                file,
                field,
                format!("`{text}`: {why} (frames are written `1-240`, `1-240x2` for every 2nd, or `1,5,9-12`)"),
            )
        };
        let number = |s: &str| -> Result<u32> {
            let s = s.trim();
            s.parse::<u32>().map_err(|_| {
                // A run of digits too long for u32 is a number, just past the largest frame.
                if !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()) {
                    bad(format!("frame {s} is past the largest frame number, {}", u32::MAX))
                } else {
                    bad(format!("`{s}` is not a frame number (0 or more)"))
                }
            })
        };
        let mut frames = Vec::new();
        if text.trim().is_empty() {
            return Err(bad("the list is empty".into()));
        }
        for part in text.split(',') {
            let (range, step) = match part.split_once('x') {
                Some((r, s)) => (r, number(s)?),
                None => (part, 1),
            };
            if step == 0 {
                return Err(bad(format!("`{}`: the step must be at least 1", part.trim())));
            }
            let (first, last) = match range.split_once('-') {
                Some((a, b)) => (number(a)?, number(b)?),
                None if part.contains('x') => return Err(bad(format!("`{}`: a step needs a range, `A-BxS`", part.trim()))),
                None => {
                    let f = number(range)?;
                    (f, f)
                }
            };
            if last < first {
                return Err(bad(format!("`{}` runs backwards; write it `{last}-{first}`", part.trim())));
            }
            if (last - first) as usize / step as usize + frames.len() >= MAX_FRAMES {
                return Err(bad(format!("more than {MAX_FRAMES} frames")));
            }
            frames.extend((first..=last).step_by(step as usize));
        }
        frames.sort_unstable();
        if let Some(w) = frames.windows(2).find(|w| w[0] == w[1]) {
            return Err(bad(format!("frame {} is listed twice", w[0])));
        }
        Ok(FrameList(frames))
    }

    /// The frames of `frames`, sorted, each once.
    pub fn of(mut frames: Vec<u32>) -> FrameList {
        frames.sort_unstable();
        frames.dedup();
        FrameList(frames)
    }

    /// One frame.
    pub fn single(frame: u32) -> FrameList {
        FrameList(vec![frame])
    }

    /// The frames.
    pub fn frames(&self) -> &[u32] {
        &self.0
    }

    /// Chunk `index` of `count` contiguous chunks whose sizes differ by at most one (the first
    /// `len % count` chunks hold one more); empty when there are more chunks than frames. The
    /// split depends only on the list and `count`, so every task of a farm job computes the same.
    pub fn chunk(&self, index: usize, count: usize) -> FrameList {
        let n = self.0.len();
        let start = |i: usize| i * (n / count) + i.min(n % count);
        FrameList(self.0[start(index)..start(index + 1)].to_vec())
    }
}

impl std::fmt::Display for FrameList {
    /// Runs of consecutive frames as `A-B`, the runs and single frames with commas: `1-8`,
    /// `1,3`, `3-5,9`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_empty() {
            return write!(f, "none");
        }
        let runs: Vec<String> = self
            .0
            .chunk_by(|a, b| a.checked_add(1) == Some(*b))
            .map(|run| match run {
                [a, .., b] => format!("{a}-{b}"),
                _ => run[0].to_string(),
            })
            .collect();
        write!(f, "{}", runs.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(t: &str) -> Vec<u32> {
        FrameList::parse(t, "command line", "--frames").unwrap().0
    }

    #[test]
    fn the_grammar() {
        assert_eq!(frames("1-5"), [1, 2, 3, 4, 5]);
        assert_eq!(frames("1-9x2"), [1, 3, 5, 7, 9]);
        assert_eq!(frames("1-10x4"), [1, 5, 9]);
        assert_eq!(frames("1,5,9-12"), [1, 5, 9, 10, 11, 12]);
        assert_eq!(frames(" 7 "), [7]);
        assert_eq!(frames("12,3"), [3, 12]);
        assert_eq!(FrameList::parse("1-4", "f", "k").unwrap().to_string(), "1-4");
        assert_eq!(FrameList::parse("1,3", "f", "k").unwrap().to_string(), "1,3");
        assert_eq!(FrameList::of(vec![9, 3, 4, 5, 4]).to_string(), "3-5,9");
    }

    #[test]
    fn bad_lists_say_why() {
        for (t, why) in [
            ("", "empty"),
            ("5-1", "backwards"),
            ("1-5x0", "step"),
            ("1,,2", "not a frame number"),
            ("a-b", "not a frame number"),
            ("-3", "not a frame number"),
            ("1-3,2", "twice"),
            ("4x2", "needs a range"),
            ("0-4000000000", "more than"),
            ("99999999999", "frame 99999999999 is past the largest frame number, 4294967295"),
        ] {
            let e = FrameList::parse(t, "command line", "--frames").unwrap_err().to_string();
            assert!(e.contains("--frames") && e.contains(why), "{t}: {e}");
        }
    }

    #[test]
    fn chunks_cover_the_list_once_in_order() {
        let all = FrameList::parse("1-10", "f", "k").unwrap();
        for count in 1..=12 {
            let joined: Vec<u32> = (0..count).flat_map(|i| all.chunk(i, count).0).collect();
            assert_eq!(joined, all.0, "{count} chunks");
            let sizes: Vec<usize> = (0..count).map(|i| all.chunk(i, count).0.len()).collect();
            assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1, "{sizes:?}");
        }
        assert_eq!(all.chunk(0, 4).0, [1, 2, 3]);
        assert_eq!(all.chunk(3, 4).0, [9, 10]);
    }
}
