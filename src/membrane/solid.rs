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
//!
//! A fused cloud whose carving no completed solid bounds may still have
//! its unseen side's depth bounded along the latest view (`membrane.view.back`,
//! [`super::view::BackBound`]): beyond that bound the inward force acts in
//! the same way.

use super::view::FreeSpace;
use crate::cloud::Vec3;
use crate::spatial::KnnIndex;

/// Which of a completion's candidate points join the fused ones.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Admission {
    /// Candidates within this distance of a fused point are dropped.
    pub gap: f64,
    /// Largest share of the candidates beyond the gap that some view saw
    /// empty by more than `tolerance`: more, and the views disagree with
    /// the completion.
    pub max_contradicted: f64,
    /// How far (m) beyond what a view saw a candidate must lie for the
    /// view to contradict it: the fused points' spacing, the resolution
    /// the completion is built at.
    pub tolerance: f64,
    /// At most this many points are added.
    pub cap: f64,
}

impl Admission {
    /// The `candidates` farther than the gap from every fused point of
    /// `index` that no view saw empty; `None` when the views contradict
    /// the completion, or more than the cap remain.
    pub(crate) fn admit(
        &self,
        candidates: impl Iterator<Item = Vec3>,
        index: &KnnIndex,
        free: &dyn FreeSpace,
    ) -> Option<Vec<Vec3>> {
        let gap2 = self.gap * self.gap;
        let mut seen_free = 0usize;
        let added: Vec<Vec3> = candidates
            .filter(|q| index.nearest_one(q).0 > gap2)
            .filter(|q| {
                let free = free.is_seen_free_beyond(q, self.tolerance);
                seen_free += usize::from(free);
                !free
            })
            .collect();
        let total = (seen_free + added.len()).max(1) as f64;
        let contradicted = seen_free as f64 > self.max_contradicted * total;
        (!contradicted && added.len() as f64 <= self.cap).then_some(added)
    }
}

/// A completed solid with its carving margin.
#[derive(Debug, Clone)]
pub enum Solid {
    /// A solid of revolution ([`super::revolution`]).
    Revolution(super::revolution::Solid),
    /// A ball ([`super::sphere`]), and the margin beyond its sphere.
    Ball(super::sphere::Ball, f64),
    /// No completed solid, but a bound on the depth of the unseen side
    /// (`membrane.view.back`, [`super::view::BackBound`]).
    Back(super::view::BackBound),
}

impl Solid {
    /// Whether `p` lies beyond the solid by more than its margin.
    pub fn is_beyond(&self, p: &Vec3) -> bool {
        match self {
            Self::Revolution(s) => s.is_beyond(p),
            Self::Ball(b, margin) => (p - b.centre).norm() > b.radius + margin,
            Self::Back(b) => b.is_beyond(p),
        }
    }
}
