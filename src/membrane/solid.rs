//! The solid a fused cloud was completed to, and the bound it sets on the
//! unseen side (`carve_delta` of `membrane.view.revolution` and
//! `membrane.view.sphere`).
//!
//! A fused cloud's inward force acts only where a view saw empty
//! ([`super::view::Seen`]), so a lobe that an early view left behind the
//! object stays wherever later views cannot see past it, however well the
//! completion closes the object. Beyond the completed solid by more than
//! its margin, the inward force acts as in space seen empty. Measured on
//! the bottles of the 39 sequences: their largest volume ratio 1.86–1.94 →
//! 1.26–1.44 ([`super::revolution`]).

use crate::cloud::Vec3;

/// A completed solid with its carving margin.
#[derive(Debug, Clone)]
pub enum Solid {
    /// A solid of revolution ([`super::revolution`]).
    Revolution(super::revolution::Solid),
    /// A ball ([`super::sphere`]), and the margin beyond its sphere.
    Ball(super::sphere::Ball, f64),
}

impl Solid {
    /// Whether `p` lies beyond the solid by more than its margin.
    pub fn is_beyond(&self, p: &Vec3) -> bool {
        match self {
            Self::Revolution(s) => s.is_beyond(p),
            Self::Ball(b, margin) => (p - b.centre).norm() > b.radius + margin,
        }
    }
}
