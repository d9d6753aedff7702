//! Rigid motions of the simulated objects and of the camera, frame by frame.
//!
//! Poses are in the fixed world frame, which is the camera's optical frame at
//! frame 0 (x right, y down, z forward). The motions are the ones a robot's
//! camera sees (issue 20, deliver 1): an object turning in place by up to
//! 360° about the vertical, an object picked up, carried and set down, the
//! camera orbiting a static object (see [`CameraPath`]), and the legacy
//! smooth drift with wobble and spin ([`Drift`]). An object swapped for
//! another on the same stream is two objects with disjoint presence ranges
//! (see `SceneObject::present` in [`crate::synth`]).

use nalgebra::{Isometry3, Translation3, UnitQuaternion};

use crate::cloud::Vec3;

/// The world's vertical, pointing up: −y of the optical frame.
pub const UP: Vec3 = Vec3::new(0.0, -1.0, 0.0);

/// Smooth drift: `pose(k) = start · T(v·k + a·sin(2πk/P)) · R(ω·k)`, the
/// translation in the world frame and the rotation about the object's own origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drift {
    /// Translation per frame (m), in the world frame.
    pub velocity: Vec3,
    /// Rotation per frame as a scaled axis (rad), in the object frame.
    pub angular_velocity: Vec3,
    /// Amplitude of a sinusoidal wobble added to the translation (m).
    pub wobble: Vec3,
    /// Period of the wobble in frames (ignored when the wobble is zero).
    pub wobble_period: f64,
}

/// How an object moves over the frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// It stays at its start pose.
    Still,
    /// Smooth drift, wobble and spin.
    Drift(Drift),
    /// It turns in place about a world axis through its origin by `per_frame`
    /// radians each frame.
    Turn {
        /// Unit axis in the world frame.
        axis: Vec3,
        /// Angle per frame (rad).
        per_frame: f64,
    },
    /// Rest, lift and tilt, carry, set down, rest: over frames `0..frames`
    /// the object rests for the first and last fifth, rises by `lift` while
    /// tilting by up to `tilt` (scaled axis, world frame), moves by `shift`
    /// and comes down again at the shifted spot. Smooth-step profiles.
    PickPlace {
        /// Length of the manoeuvre in frames.
        frames: usize,
        /// Highest displacement (m), world frame.
        lift: Vec3,
        /// Displacement from the pick spot to the place spot (m), world frame.
        shift: Vec3,
        /// Largest tilt while carried (scaled axis, rad), world frame.
        tilt: Vec3,
    },
}

/// `3s² − 2s³` on `s` clamped to `[0, 1]`.
fn smoothstep(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

impl Motion {
    /// No motion.
    pub fn still() -> Self {
        Self::Still
    }

    /// A turn about the world vertical by `total` radians over `frames`
    /// frames (frame 0 at the start angle, the last frame at `total`).
    pub fn turn(total: f64, frames: usize) -> Self {
        Self::Turn {
            axis: UP,
            per_frame: total / (frames.max(2) - 1) as f64,
        }
    }

    /// Pose at frame `k` (object frame → world) given the pose at frame 0.
    pub fn pose_at(&self, start: &Isometry3<f64>, k: usize) -> Isometry3<f64> {
        match self {
            Self::Still => *start,
            Self::Drift(d) => d.pose_at(start, k),
            Self::Turn { axis, per_frame } => {
                let spin = UnitQuaternion::from_scaled_axis(axis * (per_frame * k as f64));
                Isometry3::from_parts(start.translation, spin * start.rotation)
            }
            Self::PickPlace {
                frames,
                lift,
                shift,
                tilt,
            } => {
                let s = k as f64 / (frames.max(&2) - 1) as f64;
                // Up over [0.2, 0.4], carried over [0.35, 0.65], down over [0.6, 0.8].
                let up = smoothstep((s - 0.2) / 0.2) - smoothstep((s - 0.6) / 0.2);
                let across = smoothstep((s - 0.35) / 0.3);
                let offset = lift * up + shift * across;
                let tip = UnitQuaternion::from_scaled_axis(tilt * up);
                Isometry3::from_parts(
                    Translation3::from(start.translation.vector + offset),
                    tip * start.rotation,
                )
            }
        }
    }
}

impl Drift {
    /// Pose at frame `k` given the pose at frame 0.
    pub fn pose_at(&self, start: &Isometry3<f64>, k: usize) -> Isometry3<f64> {
        let k = k as f64;
        let wob = if self.wobble_period > 0.0 {
            self.wobble * (std::f64::consts::TAU * k / self.wobble_period).sin()
        } else {
            Vec3::zeros()
        };
        let shift = Translation3::from(self.velocity * k + wob);
        let spin = UnitQuaternion::from_scaled_axis(self.angular_velocity * k);
        let mut pose = *start;
        pose.append_translation_mut(&shift);
        pose.rotation *= spin;
        pose
    }
}

/// Where the camera is: its optical frame → world, frame by frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CameraPath {
    /// The camera stays at the world origin (the world is its optical frame).
    Fixed,
    /// The camera orbits `centre` about the world vertical by `per_frame`
    /// radians each frame, starting at the world origin and always facing the
    /// same way relative to the centre (a turntable seen from the camera,
    /// the other way round).
    Orbit {
        /// Centre of the orbit (world frame).
        centre: Vec3,
        /// Angle per frame (rad).
        per_frame: f64,
    },
}

impl CameraPath {
    /// An orbit about `centre` by `total` radians over `frames` frames.
    pub fn orbit(centre: Vec3, total: f64, frames: usize) -> Self {
        Self::Orbit {
            centre,
            per_frame: total / (frames.max(2) - 1) as f64,
        }
    }

    /// Camera pose at frame `k` (optical frame → world).
    pub fn pose_at(&self, k: usize) -> Isometry3<f64> {
        match self {
            Self::Fixed => Isometry3::identity(),
            Self::Orbit { centre, per_frame } => {
                let r = UnitQuaternion::from_scaled_axis(UP * (per_frame * k as f64));
                // T(c) · R · T(−c): a rotation about the vertical through the centre.
                Isometry3::from_parts(Translation3::from(centre - r * centre), r)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turn_reaches_its_total_angle_in_place() {
        let start = Isometry3::translation(0.1, 0.0, 1.0);
        let m = Motion::turn(std::f64::consts::PI, 30);
        let end = m.pose_at(&start, 29);
        assert!((end.rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
        assert!((end.translation.vector - start.translation.vector).norm() < 1e-15);
        let half = m.pose_at(&start, 0);
        assert_eq!(half, start);
    }

    #[test]
    fn pick_and_place_rests_lifts_and_sets_down_elsewhere() {
        let start = Isometry3::translation(0.0, 0.0, 1.0);
        let m = Motion::PickPlace {
            frames: 21,
            lift: Vec3::new(0.0, -0.1, 0.0),
            shift: Vec3::new(0.2, 0.0, 0.0),
            tilt: Vec3::new(0.0, 0.0, 0.3),
        };
        for k in 0..=4 {
            assert_eq!(m.pose_at(&start, k), start, "rests at frame {k}");
        }
        let top = m.pose_at(&start, 10);
        assert!((top.translation.vector.y + 0.1).abs() < 1e-9, "{top}");
        assert!((top.rotation.angle() - 0.3).abs() < 1e-9);
        let end = m.pose_at(&start, 20);
        assert!((end.translation.vector - Vec3::new(0.2, 0.0, 1.0)).norm() < 1e-12);
        assert!(end.rotation.angle() < 1e-12);
    }

    #[test]
    fn an_orbiting_camera_keeps_its_distance_and_view_of_the_centre() {
        let c = Vec3::new(0.0, 0.0, 1.0);
        let path = CameraPath::orbit(c, std::f64::consts::PI, 11);
        assert_eq!(path.pose_at(0), Isometry3::identity());
        for k in 0..11 {
            let cam = path.pose_at(k);
            // The centre, seen from the camera, stays straight ahead at 1 m.
            let seen = cam.inverse() * nalgebra::Point3::from(c);
            assert!(
                (seen.coords - Vec3::new(0.0, 0.0, 1.0)).norm() < 1e-12,
                "{k}"
            );
        }
        // Half way round the camera stands behind the centre.
        let back = path.pose_at(10).translation.vector;
        assert!((back - Vec3::new(0.0, 0.0, 2.0)).norm() < 1e-12, "{back}");
    }
}
