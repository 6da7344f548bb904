//! The error type of the crate.

use std::path::{Path, PathBuf};

/// What can go wrong while drawing a picture; each names its file, and
/// plotters' own errors are kept as text (their types vary by backend).
#[derive(Debug, thiserror::Error)]
pub enum DrawError {
    /// The picture file could not be created.
    #[error("creating {}: {message}", path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// plotters could not draw into the picture.
    #[error("drawing {}: {message}", path.display())]
    Draw {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// A panel of a figure could not be drawn (it had nothing to plot, or
    /// plotters failed).
    #[error("{panel} in {}: {message}", path.display())]
    Panel {
        /// The panel's title.
        panel: String,
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// plotters could not draw into pixels in memory ([`crate::rgb`]).
    #[error("drawing pixels: {message}")]
    Raster {
        /// Why.
        message: String,
    },
    /// The finished picture could not be written.
    #[error("writing {}: {message}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

impl DrawError {
    pub(crate) fn create(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Create {
            path: path.to_owned(),
            message: e.to_string(),
        }
    }

    pub(crate) fn draw(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Draw {
            path: path.to_owned(),
            message: e.to_string(),
        }
    }

    pub(crate) fn raster(e: impl std::fmt::Display) -> Self {
        Self::Raster {
            message: e.to_string(),
        }
    }

    pub(crate) fn write(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Write {
            path: path.to_owned(),
            message: e.to_string(),
        }
    }
}
