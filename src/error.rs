//! Crate-level error type.
//!
//! Each module defines its own `thiserror` enum that names the failing input
//! and the problem; [`Error`](enum@Error) wraps them so that callers that cross module
//! boundaries (the CLI, the frame pipeline, the node) can use one type.
//! Errors are reported exactly once, by whoever handles them.

use thiserror::Error;

/// Any error sepmem's library can return.
#[derive(Debug, Error)]
pub enum Error {
    /// A configuration file or override could not be read or applied.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// An input cloud or mesh was unusable (empty, degenerate, inconsistent).
    #[error(transparent)]
    Cloud(#[from] crate::cloud::CloudError),
    /// A file could not be read or written.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
    /// A ROS 2 message could not be encoded or decoded.
    #[error(transparent)]
    Wire(#[from] crate::wire::WireError),
    /// A PointCloud2 could not be turned into points.
    #[error(transparent)]
    PointCloud2(#[from] crate::wire::pointcloud2::PointCloud2Error),
}

/// Result alias using the crate-level [`Error`](enum@Error).
pub type Result<T, E = Error> = std::result::Result<T, E>;
