//! One error type for the data layer: every variant names the file it is about.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file exists but its content is wrong (bad magic, truncated, NaN, out of range…).
    #[error("{}: {msg}", path.display())]
    Invalid { path: PathBuf, msg: String },
    /// The operating system refused (missing file, permissions, disk full…).
    #[error("{}: {err}", path.display())]
    Io {
        path: PathBuf,
        // Not a `source`: the message already ends with it, and error chains printed
        // with `{:#}` would repeat it.
        err: std::io::Error,
    },
    /// An error that is not about one file (bad arguments, inconsistent settings).
    #[error("{0}")]
    Other(String),
}

pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    pub fn invalid(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }

    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err: source,
        }
    }
}

/// Attach a path to an `io::Result`.
pub trait IoContext<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T> {
        self.map_err(|e| Error::io(path, e))
    }
}
