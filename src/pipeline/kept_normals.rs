//! The fused model's normals kept from frame to frame for its registration
//! (`pipeline.model_icp.keep_normals`).
//!
//! The model registration (`pipeline.model_icp`,
//! [`super::align::align_to_points`]) takes point-to-plane steps on the
//! normals of the model points a frame matches, each from the model
//! points nearest to it. On the 6 k-point turning mug those normals were
//! 60 % of the registration's time, and a finer pass on 2 000 of the
//! frame's points (`model_icp.refine`) cost 5.5 ms a frame more, most of
//! it in the normals of the points only it matches. A voxel of the fused
//! model keeps its place in the object's frame, and its normal changes
//! little while new views refine the voxel's mean: a normal estimated in
//! one frame is kept, in the object's frame and keyed by its voxel, for
//! the next `keep_normals` frames.

use super::align::Rigid;
use crate::cloud::Vec3;
use crate::spatial::{cell_key, FixedMap};

/// Normals of the fused model's voxels, in the object's frame, each with
/// the frame it was estimated in.
#[derive(Debug, Clone, Default)]
pub(super) struct KeptNormals {
    /// The voxel edge the keys are cells of.
    edge: f64,
    /// Frames counted since the first.
    frame: u32,
    kept: FixedMap<[i32; 3], (Vec3, u32)>,
}

impl KeptNormals {
    /// Start a frame of a model with voxels of `edge`: forget the normals
    /// estimated `keep` frames ago or earlier, and all of them when the
    /// voxels changed (a new model).
    pub fn next_frame(&mut self, edge: f64, keep: u32) {
        self.frame = self.frame.wrapping_add(1);
        if edge != self.edge {
            self.kept.clear();
            self.edge = edge;
        }
        let frame = self.frame;
        self.kept
            .retain(|_, (_, at)| frame.wrapping_sub(*at) < keep);
    }

    /// The cell of the object-frame point `p`.
    fn key(&self, p: &Vec3) -> [i32; 3] {
        cell_key(p, self.edge)
    }

    /// The kept normal of the voxel holding `p`, both in the cloud frame
    /// that `pose` (object → cloud) maps the object into.
    pub fn get(&self, pose: &Rigid, p: &Vec3) -> Option<Vec3> {
        let local = pose.inverse_transform_point(&(*p).into()).coords;
        let (n, _) = self.kept.get(&self.key(&local))?;
        Some(pose.rotation * n)
    }

    /// Keep `n` as the normal of the voxel holding `p`, both in the cloud
    /// frame that `pose` (object → cloud) maps the object into.
    pub fn put(&mut self, pose: &Rigid, p: &Vec3, n: &Vec3) {
        let local = pose.inverse_transform_point(&(*p).into()).coords;
        let key = self.key(&local);
        let n = pose.rotation.inverse_transform_vector(n);
        self.kept.insert(key, (n, self.frame));
    }

    /// Normals kept.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.kept.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_normal_is_kept_for_the_given_frames_and_forgotten_with_its_voxels() {
        let mut kept = KeptNormals::default();
        let at = Rigid::identity();
        let (p, n) = (Vec3::new(0.012, -0.004, 0.031), Vec3::z());
        kept.next_frame(0.01, 3);
        kept.put(&at, &p, &n);
        // Anywhere in the same 1 cm voxel; not in the next one.
        assert_eq!(kept.get(&at, &Vec3::new(0.0101, -0.0099, 0.0399)), Some(n));
        assert_eq!(kept.get(&at, &Vec3::new(0.0201, -0.004, 0.031)), None);
        kept.next_frame(0.01, 3);
        kept.next_frame(0.01, 3);
        assert_eq!(kept.get(&at, &p), Some(n));
        kept.next_frame(0.01, 3);
        assert_eq!((kept.get(&at, &p), kept.len()), (None, 0));
        kept.put(&at, &p, &n);
        kept.next_frame(0.02, 3);
        assert_eq!(kept.get(&at, &p), None);
    }

    #[test]
    fn a_normal_is_kept_in_the_objects_frame() {
        // Kept under one pose, found under the next at the moved point,
        // turned with it.
        let mut kept = KeptNormals::default();
        kept.next_frame(0.01, 3);
        let (p, n) = (Vec3::new(0.105, 0.205, 0.305), Vec3::x());
        let first = Rigid::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, 0.0, 0.5));
        let moved = Rigid::new(Vec3::new(0.5, 2.0, 3.0), Vec3::new(0.3, 0.0, 0.9));
        let cloud = |pose: &Rigid| (pose.transform_point(&p.into()).coords, pose.rotation * n);
        let (p1, n1) = cloud(&first);
        kept.put(&first, &p1, &n1);
        let (p2, n2) = cloud(&moved);
        let got = kept.get(&moved, &p2).unwrap();
        assert!((got - n2).norm() < 1e-12, "{got:?} vs {n2:?}");
        assert_eq!(kept.get(&first, &p2), None);
    }
}
