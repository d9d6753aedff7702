//! Closed cubic B-spline surfaces: the membrane's shape model (paper Eq. 10).
//!
//! `S(u,v) = Σ_i Σ_j N_{i,3}(u) N_{j,3}(v) Q_{i,j}`, periodic in `u` (M control
//! columns), clamped in `v` (L control rows whose first and last rows collapse
//! to the two poles). The paper relies on this representation for the
//! membrane's internal energy: the B-spline keeps the surface smooth, so only
//! the external (separability) energy is optimised.
//!
//! * [`basis`]: periodic and clamped cubic basis functions with derivatives;
//! * [`surface`]: the control net, evaluation, outward normals, exact u-doubling;
//! * [`fit`]: the least-squares refit with a roughness penalty, factored once
//!   per sample layout (paper step 4), and shape-keeping regridding (§III-F).

pub mod basis;
pub mod fit;
pub mod surface;

pub use fit::{param_stretch, redistribute, regrid, FitSystem};
pub use surface::{ClosedSurface, Layout, SurfacePoint};

use thiserror::Error;

/// Errors from the spline surface and its fit.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SplineError {
    /// The control grid or the sample grid is too small for a cubic closed surface.
    #[error(
        "control grid {m}x{l} with {u_n}x{v_n} samples is too small (need M>=4, L>=4, samples>0)"
    )]
    GridTooSmall {
        /// Control columns.
        m: usize,
        /// Control rows.
        l: usize,
        /// Samples along u.
        u_n: usize,
        /// Samples along v.
        v_n: usize,
    },
    /// A control net does not have M·L points.
    #[error("control net for {m}x{l} needs {} points, got {got}", m * l)]
    NetSize {
        /// Control columns.
        m: usize,
        /// Control rows.
        l: usize,
        /// Points given.
        got: usize,
    },
    /// The number of fit targets differs from the layout's sample count.
    #[error("fit expects {expected} target samples, got {got}")]
    SampleCount {
        /// Samples in the layout.
        expected: usize,
        /// Targets given.
        got: usize,
    },
    /// A surface was fitted with a system built for another grid size.
    #[error("surface grid {surface:?} does not match fit system grid {system:?}")]
    GridMismatch {
        /// Surface (M, L).
        surface: (usize, usize),
        /// System (M, L).
        system: (usize, usize),
    },
    /// The normal matrix is not positive definite.
    #[error("least-squares normal matrix is singular at row {row}")]
    Singular {
        /// Row where the factorisation failed.
        row: usize,
    },
    /// A control point or fit result is NaN or infinite.
    #[error("control net contains non-finite coordinates")]
    NonFinite,
}
