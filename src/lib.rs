//! # sepmem: the Separability Membrane as a perception node
//!
//! sepmem implements the *Separability Membrane* of Pratamasunu, Hao and Fukui
//! (2025): a closed cubic B-spline surface that wraps one object's point cloud
//! and moves, sample by sample, toward the position of maximum class
//! separability between the inside and the outside of a cuboid search region.
//!
//! The crate is organised by concept:
//!
//! | module | what it holds |
//! |---|---|
//! | [`cloud`] | the point cloud type (positions plus named scalar attributes), bounding boxes |
//! | [`mesh`] | the indexed triangle mesh produced by the membrane, with per-vertex scalars |
//! | [`config`] | the one annotated configuration (`launch/sepmem.json5`), loading and `--set` overrides |
//! | [`error`] | the crate-level error type |
//! | [`node`] | the live node: per-stream keep-latest slots, rayon compute, diagnostics, eviction, sharding |
//! | [`transport`] | ROS 2 wire compatibility over zenoh: rmw_zenoh keys, attachments, liveliness tokens; sessions |
//!
//! Every module's own documentation cites the paper's equations it implements.
#![cfg_attr(test, allow(clippy::unwrap_used))]

pub mod cloud;
pub mod config;
pub mod error;
pub mod mesh;
pub mod node;
pub mod transport;

pub use cloud::{Aabb, Attribute, PointCloud, Vec3};
pub use error::{Error, Result};
pub use mesh::TriMesh;
