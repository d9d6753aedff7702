//! Separability of adjacent regions of a point cloud (paper §III-A..C).
//!
//! * [`point`]: point separability η_p from actual and estimated non-data
//!   counts (paper Eqs. 4, 7, 8);
//! * [`attribute`]: attribute separability (Fisher ratio, Eq. 1) and the
//!   weighted separability (Eq. 9);
//! * [`filter`]: the 3D separability filter, a separability map of a cloud (§IV-A);
//! * [`grid`]: the spatial index that gathers the points of a search cuboid;
//! * [`search`]: the oriented search primitive: the separability profile
//!   over K boundary positions along a direction, and its argmax.

pub mod attribute;
pub mod filter;
pub mod grid;
pub mod point;
pub mod search;

pub use attribute::{
    AttributeChannel, AttributeError, AttributeSet, AttributeWeights, ChannelWeight,
};
pub use filter::{separability_map, separability_map_of, FilterDirection, FilterError, FilterSize};
pub use grid::{GridError, OrientedBox, SpatialIndex};
pub use point::{
    capacities, capacity, eta_from_counts, eta_phi2, eta_phi2_ratio, non_data_count,
    point_separability, PointSeparability,
};
pub use search::{
    Best, BestRule, BoundaryStats, Cuboid, Delta, SearchError, SearchOutcome, SearchScratch,
    Searcher,
};

use serde::{Deserialize, Serialize};

/// The `separability` configuration section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeparabilityConfig {
    /// Number K of boundary positions tried in each search cuboid.
    pub boundaries: usize,
    /// Use the local δ_R of each cuboid (paper Eq. 6) instead of the cloud's global δ.
    pub local_delta: bool,
    /// Weights of the separability vector [η_p, η_a1, …] (paper Eq. 9).
    pub weights: AttributeWeights,
    /// Radius of the local-density attribute, in units of the global δ.
    pub density_radius: f64,
    /// Neighbours of the PCA normals used by `sepmem filter --direction normal`.
    pub normal_k: usize,
}

impl Default for SeparabilityConfig {
    fn default() -> Self {
        Self {
            boundaries: 30,
            local_delta: false,
            weights: AttributeWeights::default(),
            density_radius: 2.0,
            normal_k: 16,
        }
    }
}
