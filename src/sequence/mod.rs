//! Animation: frame patterns in file names ([`pattern`]), frame lists and their farm chunks
//! ([`frames`]), keyframes ([`animation`]), and the scene description of each frame
//! ([`Sequence`]).

pub mod animation;
pub mod frames;
pub mod pattern;

pub use animation::Animation;
pub use frames::FrameList;
pub use pattern::FramePattern;

use crate::error::{Error, Result};
use crate::scene::SceneDesc;
use std::path::{Path, PathBuf};

/// A scene file seen as a sequence: its description, its grid pattern and its keyframes.
#[derive(Clone, Debug)]
pub struct Sequence {
    desc: SceneDesc,
    grid: Option<FramePattern>,
    animation: Animation,
    frames: Option<FrameList>,
}

/// Most missing frame files one message lists.
const MISSING_LISTED: usize = 5;

impl Sequence {
    /// Read the animation out of `desc` (`file` names it in messages).
    pub fn new(desc: &SceneDesc, file: &str) -> Result<Sequence> {
        let grid = match desc.medium.grid.as_str() {
            "procedural" => None,
            g => FramePattern::parse(g, file, "medium.grid")?,
        };
        let a = desc.animation.clone().unwrap_or_default();
        let frames = a
            .frames
            .as_deref()
            .map(|f| FrameList::parse(f, file, "animation.frames"))
            .transpose()?;
        let animation = Animation::new(&a, desc, file)?;
        let mut desc = desc.clone();
        desc.animation = None;
        Ok(Sequence {
            desc,
            grid,
            animation,
            frames,
        })
    }

    /// Whether anything changes from frame to frame (a grid pattern or a keyed channel).
    pub fn is_animated(&self) -> bool {
        self.grid.is_some() || self.animation.is_keyed()
    }

    /// Whether the sun changes from frame to frame (a key sets its direction or irradiance).
    pub fn keys_sun(&self) -> bool {
        self.animation.keys_sun()
    }

    /// The scene's own frames (`animation.frames`).
    pub fn frames(&self) -> Option<&FrameList> {
        self.frames.as_ref()
    }

    /// The description of `frame`: its grid file and every keyed channel's value.
    pub fn desc_at(&self, frame: u32) -> SceneDesc {
        let mut d = self.desc.clone();
        if let Some(g) = &self.grid {
            d.medium.grid = g.name(frame);
        }
        self.animation.apply(&mut d, frame);
        d
    }

    /// Every grid file `frames` read (a `.raw` grid's `.json` sidecar too) exists, relative to
    /// `base`; else one error naming the missing frames. Checked before any frame renders.
    pub fn check_grid_files(&self, frames: &[u32], base: &Path, file: &str) -> Result<()> {
        let Some(g) = &self.grid else {
            return Ok(());
        };
        let needed = |f: u32| -> Vec<PathBuf> {
            let p = base.join(g.name(f));
            let raw = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("raw"));
            if raw {
                vec![p.with_extension("json"), p]
            } else {
                vec![p]
            }
        };
        let missing: Vec<(u32, PathBuf)> = frames
            .iter()
            .flat_map(|&f| needed(f).into_iter().filter(|p| !p.is_file()).map(move |p| (f, p)))
            .collect();
        let Some((first, path)) = missing.first() else {
            return Ok(());
        };
        let listed: Vec<String> = missing
            .iter()
            .take(MISSING_LISTED)
            .map(|(f, p)| format!("frame {f} (`{}`)", p.display()))
            .collect();
        let more = missing.len().saturating_sub(MISSING_LISTED);
        Err(Error::invalid(
            file,
            "medium.grid",
            format!(
                "{} missing: {}{}; the pattern `{}` names frame {first} `{}`; choose frames that exist (render --frames, export --frame)",
                if missing.len() == 1 { "a frame file is" } else { "frame files are" },
                listed.join(", "),
                if more > 0 { format!(" and {more} more") } else { String::new() },
                self.desc.medium.grid,
                path.display()
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_frame_is_named() {
        let dir = tempfile::tempdir().unwrap();
        for f in [1, 2, 4] {
            std::fs::write(dir.path().join(format!("c.{f:04}.npy")), b"x").unwrap();
        }
        let desc = SceneDesc::from_toml("[medium]\ngrid = \"c.####.npy\"\n", "s.toml").unwrap();
        let seq = Sequence::new(&desc, "s.toml").unwrap();
        assert!(seq.is_animated());
        assert_eq!(seq.desc_at(3).medium.grid, "c.0003.npy");
        assert!(seq.check_grid_files(&[1, 2, 4], dir.path(), "s.toml").is_ok());
        let e = seq.check_grid_files(&[1, 2, 3, 4], dir.path(), "s.toml").unwrap_err().to_string();
        assert!(
            e.contains("medium.grid") && e.contains("frame 3") && e.contains("c.0003.npy"),
            "{e}"
        );
    }

    #[test]
    fn a_still_scene_is_not_animated() {
        let seq = Sequence::new(&SceneDesc::default(), "s").unwrap();
        assert!(!seq.is_animated() && seq.frames().is_none());
        assert_eq!(seq.desc_at(7), SceneDesc::default());
    }
}
