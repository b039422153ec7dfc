//! The one error type of the library. Every message names the file (or "built-in scene"),
//! the field or place at fault, and what is allowed, so a user can fix the input.

use std::path::PathBuf;

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong, with enough context to act on.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A value in the scene (or on the command line) is out of range or inconsistent.
    #[error("{file}: field `{field}`: {message}")]
    Invalid {
        /// The scene file, or `built-in scene` / `command line`.
        file: String,
        /// Dotted path of the offending key, e.g. `medium.sigma_t`.
        field: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// The scene file is not valid TOML or has an unknown key.
    #[error("{file}: {message}")]
    Parse {
        /// The scene file.
        file: String,
        /// The parser's message, which names the key and line.
        message: String,
    },
    /// A data file (grid, image) is malformed: truncated, corrupt or unsupported.
    #[error("{file}: {message}")]
    Format {
        /// The offending file.
        file: String,
        /// What is wrong with it and, where possible, how to fix it.
        message: String,
    },
    /// An operating-system I/O error on a named path.
    #[error("{path}: {source}")]
    Io {
        /// The path being read or written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A numerical stage failed to do its job (e.g. the solver did not converge).
    #[error("{stage}: {message}")]
    Numerical {
        /// The stage, e.g. `diffusion solver`.
        stage: String,
        /// What happened and what to try.
        message: String,
    },
    /// The caller cancelled the render ([`crate::Options::cancel`]); nothing was produced.
    #[error("render cancelled")]
    Cancelled,
}

impl Error {
    /// Shorthand for [`Error::Invalid`].
    pub fn invalid(file: impl Into<String>, field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            file: file.into(),
            field: field.into(),
            message: message.into(),
        }
    }

    /// Shorthand for [`Error::Format`].
    pub fn format(file: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Format {
            file: file.into(),
            message: message.into(),
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
}

/// Check a finite number; `what` describes the allowed range for the message.
pub fn check(file: &str, field: &str, ok: bool, value: impl std::fmt::Debug, what: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(file, field, format!("{value:?} is not allowed: {what}")))
    }
}

pub fn finite3(v: [f32; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

pub fn rgb_in_unit(v: [f32; 3]) -> bool {
    v.iter().all(|x| (0.0..=1.0).contains(x))
}

pub fn rgb_nonneg(v: [f32; 3]) -> bool {
    v.iter().all(|x| x.is_finite() && *x >= 0.0)
}

/// Refuse a stage's output holding a non-finite value: an error naming the stage and what it
/// wrote, at the first bad element, so a numerical failure stops where it starts instead of
/// reaching the image. One pass over values the stage already holds; it changes none of them.
pub fn check_finite_field(stage: &str, what: &str, values: impl IntoIterator<Item = f32>) -> Result<()> {
    match values.into_iter().enumerate().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some((k, v)) => Err(Error::Numerical {
            stage: stage.to_string(),
            message: format!(
                "{what} holds a non-finite value ({v}, element {k}); no image was written. Please report \
                 the scene; another --method may render it meanwhile"
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_finite_field_is_an_error_naming_the_stage() {
        assert!(check_finite_field("incident light", "Q0", [0.0, 1.0, 1e30]).is_ok());
        let e = check_finite_field("incident light", "Q0", [0.0, f32::NAN, 1.0]).unwrap_err();
        let e = e.to_string();
        assert!(
            e.starts_with("incident light:") && e.contains("Q0") && e.contains("element 1"),
            "{e}"
        );
        assert!(check_finite_field("gather", "image", [f32::INFINITY]).is_err());
    }
}
