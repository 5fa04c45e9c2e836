//! The error type shared by loaders, the renderer and image output.

use std::path::PathBuf;

/// Everything that can go wrong between a scene file and an image.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene, mesh or texture file could not be read or is invalid.
    #[error("{}: {message}", path.display())]
    Load {
        /// The file at fault.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The image could not be written.
    #[error("cannot write {}: {message}", path.display())]
    Output {
        /// The output path.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// Render settings or scene content are unusable.
    #[error("{0}")]
    Invalid(String),
}

impl Error {
    /// A [`Error::Load`] for `path`.
    pub fn load(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Load {
            path: path.into(),
            message: message.into(),
        }
    }
}

/// Result with Prism's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
