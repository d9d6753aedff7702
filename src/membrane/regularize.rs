//! The regularisers between the search and the refit: they turn the
//! per-sample shifts of [`super::step`] into the shifts the refit follows.
//!
//! - **Skipped-sample fill** (sparse search): warm starts, and cold
//!   whole-object reconstructions on the final grid of a cloud at least as
//!   dense as the samples, search a checkerboard half of the samples per
//!   iteration; the other half take their searched neighbours' median shift
//!   (`step.sparse_warm_search`, `step.sparse_cold_search`).
//! - **3×3 median filter** of the shifts of moving samples (`median_filter`).
//! - **Pole tension** (`pole_tension`): near the poles, samples without a
//!   data force move by the normal component of the step to their grid
//!   neighbours' mean. A pole caught in a thick shell of outliers otherwise
//!   stays out as a thin horn that no search sees, because its samples'
//!   normals point across it.
//! - **Occluded-back smoothing** (`warm_back_smoothing`): a warm-started
//!   single view smooths its occluded back — samples behind the seen
//!   surface with no data force move by the mean-free umbrella step, so
//!   dents carried over from earlier frames fade. The measurement that
//!   keeps it (issue 19, item 4): `tests/replay.rs`,
//!   `every_warm_frame_of_a_20000_point_sequence_reaches_the_cold_f_score_of_its_frame`
//!   (a turning bowl, 20 frames): with it 19/19 warm frames within 0.01 of
//!   the cold F (largest F_cold − F_warm +0.002), without it 16/19 (+0.017);
//!   the mechanism ablation's figures move by at most 0.0008
//!   (`docs/ablation-mechanisms.md`).

use super::config::RegularizeConfig;
use super::step::{insertion_sort_by, SampleOut, SampleState};
use super::view;

/// The searched samples of one iteration on their `u_n × v_n` grid
/// (row-major, periodic in u, clamped in v).
#[derive(Clone, Copy)]
pub struct Samples<'a> {
    /// The samples.
    pub outs: &'a [SampleOut],
    /// Samples around (u, periodic).
    pub un: usize,
    /// Samples pole to pole (v).
    pub vn: usize,
}

/// Reused buffers of [`shifts`].
#[derive(Debug, Default)]
pub struct Scratch {
    back: Vec<(usize, f64)>,
}

/// The shifts the refit follows: the median-filtered (or raw) shifts, then
/// pole tension (whole objects only: the unseen back of a single view is
/// held where it is), then a warm single view's back smoothing.
pub fn shifts(
    cfg: &RegularizeConfig,
    s: Samples<'_>,
    view: Option<&view::ViewBuffer>,
    warm: bool,
    scratch: &mut Scratch,
    out: &mut Vec<f64>,
) {
    if cfg.median_filter {
        median_filter(s, out);
    } else {
        out.clear();
        out.extend(s.outs.iter().map(|o| o.shift));
    }
    if let (Some(t), None) = (&cfg.pole_tension, view) {
        pole_tension(s, t.strength, t.rows, out);
    }
    if let (Some(vb), Some(k), true) = (view, cfg.warm_back_smoothing, warm) {
        smooth_occluded_back(s, vb, k, &mut scratch.back, out);
    }
}

/// Give every [`SampleState::Skipped`] sample the result of its searched
/// 4-neighbours (periodic in u, clamped in v): the median shift of those
/// that moved (the sample stays put when none did) and the mean η of all of
/// them. `fills` is scratch.
pub fn fill_skipped(
    outs: &mut [SampleOut],
    un: usize,
    vn: usize,
    fills: &mut Vec<(usize, SampleOut)>,
) {
    fills.clear();
    for j in 0..vn {
        for i in 0..un {
            let k = j * un + i;
            if outs[k].state == SampleState::Skipped {
                fills.push((k, filled(outs, un, vn, i, j)));
            }
        }
    }
    for &(k, o) in fills.iter() {
        outs[k] = o;
    }
}

/// The result [`fill_skipped`] gives the skipped sample `(i, j)`.
fn filled(outs: &[SampleOut], un: usize, vn: usize, i: usize, j: usize) -> SampleOut {
    let k = j * un + i;
    let left = if i == 0 { un - 1 } else { i - 1 };
    let right = if i + 1 == un { 0 } else { i + 1 };
    let mut moved = [0.0f64; 4];
    let (mut n_moved, mut n_eta, mut eta) = (0usize, 0usize, 0.0);
    let mut visit = |o: &SampleOut| {
        if o.state == SampleState::Skipped {
            return;
        }
        n_eta += 1;
        eta += o.eta;
        if o.state != SampleState::Still {
            moved[n_moved] = o.shift;
            n_moved += 1;
        }
    };
    visit(&outs[j * un + left]);
    visit(&outs[j * un + right]);
    if j > 0 {
        visit(&outs[k - un]);
    }
    if j + 1 < vn {
        visit(&outs[k + un]);
    }
    let mut out = SampleOut {
        state: SampleState::Still,
        shift: 0.0,
        eta: if n_eta > 0 { eta / n_eta as f64 } else { 0.0 },
        ..outs[k]
    };
    if n_moved > 0 {
        out.shift = median_of_few(&mut moved[..n_moved]);
        out.state = SampleState::Boundary;
    }
    out
}

/// Median of a short non-empty slice (the middle pair's mean for an even
/// length); sorts it in place.
fn median_of_few(s: &mut [f64]) -> f64 {
    insertion_sort_by(s, |&x| x);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Membrane tension near the poles: each sample of the first and last
/// `rows` sample rows that has no data force gets, as its shift, `tension`
/// times its [`umbrella`] step. Writes into `shifts`.
fn pole_tension(s: Samples<'_>, tension: f64, rows: usize, shifts: &mut [f64]) {
    for j in 0..s.vn {
        if j >= rows && j + rows < s.vn {
            continue;
        }
        for i in 0..s.un {
            let k = j * s.un + i;
            if s.outs[k].state == SampleState::Still {
                shifts[k] = tension * umbrella(s, i, j);
            }
        }
    }
}

/// Normal component of the step from sample `(i, j)` to the mean of its four
/// grid neighbours (periodic in u; for the rows next to a pole, the sample
/// across the pole stands in for the missing neighbour).
fn umbrella(s: Samples<'_>, i: usize, j: usize) -> f64 {
    let (outs, un, vn) = (s.outs, s.un, s.vn);
    let k = j * un + i;
    let left = if i == 0 { un - 1 } else { i - 1 };
    let right = if i + 1 == un { 0 } else { i + 1 };
    let across = (i + un / 2) % un;
    let up = if j == 0 { across } else { k - un };
    let down = if j + 1 == vn {
        (vn - 1) * un + across
    } else {
        k + un
    };
    let q = (outs[j * un + left].p + outs[j * un + right].p + outs[up].p + outs[down].p) / 4.0;
    (q - outs[k].p).dot(&outs[k].n)
}

/// Smoothing of a warm-started single view's occluded back: every sample
/// without a data force that lies behind the seen surface moves `weight`
/// times its [`umbrella`] step minus the mean step of all such samples, so
/// dents carried over from earlier frames fade while the back as a whole
/// neither shrinks nor grows. `sel` is a reused buffer.
fn smooth_occluded_back(
    s: Samples<'_>,
    vb: &view::ViewBuffer,
    weight: f64,
    sel: &mut Vec<(usize, f64)>,
    shifts: &mut [f64],
) {
    sel.clear();
    for j in 0..s.vn {
        for i in 0..s.un {
            let o = &s.outs[j * s.un + i];
            if o.state == SampleState::Still && vb.is_occluded(&o.p) {
                sel.push((j * s.un + i, umbrella(s, i, j)));
            }
        }
    }
    if sel.is_empty() {
        return;
    }
    let mean = sel.iter().map(|s| s.1).sum::<f64>() / sel.len() as f64;
    for &(k, step) in sel.iter() {
        shifts[k] = weight * (step - mean);
    }
}

/// Median of the shifts of moving samples in each 3×3 neighbourhood
/// (periodic in u, clamped in v); samples that do not move stay put.
fn median_filter(s: Samples<'_>, shifts: &mut Vec<f64>) {
    let (outs, un, vn) = (s.outs, s.un, s.vn);
    shifts.resize(outs.len(), 0.0);
    let mut buf = [0.0f64; 9];
    for j in 0..vn {
        for i in 0..un {
            let k = j * un + i;
            if outs[k].state == SampleState::Still {
                shifts[k] = 0.0;
                continue;
            }
            let mut n = 0;
            // Periodic in u (no modulo: this runs for every sample).
            let left = if i == 0 { un - 1 } else { i - 1 };
            let right = if i + 1 == un { 0 } else { i + 1 };
            for jj in j.saturating_sub(1)..(j + 2).min(vn) {
                let row = &outs[jj * un..(jj + 1) * un];
                for ii in [left, i, right] {
                    let o = &row[ii];
                    if o.state != SampleState::Still {
                        buf[n] = o.shift;
                        n += 1;
                    }
                }
            }
            shifts[k] = median_of_few(&mut buf[..n]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::cloud::Vec3;

    fn searched(shift: f64, eta: f64, state: SampleState) -> SampleOut {
        SampleOut {
            shift,
            eta,
            state,
            ..SampleOut::default()
        }
    }

    fn samples(outs: &[SampleOut], un: usize, vn: usize) -> Samples<'_> {
        Samples { outs, un, vn }
    }

    #[test]
    fn occluded_back_smoothing_lifts_a_dent_without_moving_the_back_as_a_whole() {
        // The camera at the origin sees a sheet at z = 1; the back samples
        // lie behind it on a curved patch z = 1.2 + 3(x² + y²) (normals +z,
        // away from the camera: plain smoothing would move the patch as a
        // whole), one of them dented 0.1 toward the camera.
        let mut seen = Vec::new();
        for a in -20..=20 {
            for b in -20..=20 {
                seen.push(Vec3::new(a as f64 * 0.01, b as f64 * 0.01, 1.0));
            }
        }
        let vb = view::ViewBuffer::new(&seen, Vec3::zeros(), 0.01).unwrap();
        let (un, vn) = (8, 6);
        let mut outs = vec![SampleOut::default(); un * vn];
        for j in 0..vn {
            for i in 0..un {
                let (x, y) = (i as f64 * 0.02 - 0.07, j as f64 * 0.02 - 0.05);
                let dent = if (i, j) == (3, 2) { 0.1 } else { 0.0 };
                outs[j * un + i] = SampleOut {
                    p: Vec3::new(x, y, 1.2 + 3.0 * (x * x + y * y) - dent),
                    n: Vec3::z(),
                    ..SampleOut::default()
                };
            }
        }
        // A sample with a data force keeps its shift.
        outs[0].state = SampleState::Boundary;
        outs[0].shift = 0.5;
        let mut shifts: Vec<f64> = outs.iter().map(|o| o.shift).collect();
        let mut sel = Vec::new();
        smooth_occluded_back(samples(&outs, un, vn), &vb, 1.0, &mut sel, &mut shifts);
        assert_eq!(shifts[0], 0.5);
        let dent = shifts[2 * un + 3];
        assert!(dent > 0.08, "the dent moves back out: {dent}");
        assert!(shifts[2 * un + 2] < 0.0, "its neighbours move in a little");
        let raw: f64 = (1..un * vn)
            .map(|k| umbrella(samples(&outs, un, vn), k % un, k / un))
            .sum();
        assert!(
            raw.abs() > 0.005,
            "plain umbrella steps would move the back: {raw}"
        );
        let sum: f64 = shifts[1..].iter().sum();
        assert!(sum.abs() < 1e-12, "the back as a whole stays: {sum}");
        // Samples in front of the seen sheet are not smoothed.
        let mut front = outs.clone();
        for o in &mut front {
            o.p.z = 0.5;
            o.state = SampleState::Still;
        }
        front[2 * un + 3].p.z = 0.4;
        let mut shifts = vec![0.0; un * vn];
        smooth_occluded_back(samples(&front, un, vn), &vb, 1.0, &mut sel, &mut shifts);
        assert!(shifts.iter().all(|&s| s == 0.0));
    }

    #[test]
    fn skipped_samples_take_the_median_shift_of_their_moving_neighbours() {
        // 4 × 3 samples (u periodic), checkerboard: (i + j) odd skipped.
        let (un, vn) = (4, 3);
        let mut outs = vec![SampleOut::default(); un * vn];
        for j in 0..vn {
            for i in 0..un {
                let k = j * un + i;
                outs[k] = if (i + j) % 2 == 1 {
                    SampleOut {
                        p: Vec3::new(i as f64, j as f64, 0.0),
                        state: SampleState::Skipped,
                        ..SampleOut::default()
                    }
                } else {
                    // Shift = flat index; row 2 does not move.
                    searched(
                        k as f64,
                        0.1 * k as f64,
                        if j < 2 {
                            SampleState::Boundary
                        } else {
                            SampleState::Still
                        },
                    )
                };
            }
        }
        let mut fills = Vec::new();
        fill_skipped(&mut outs, un, vn, &mut fills);
        // (1, 0): neighbours (0,0)=0, (2,0)=2 and (1,1)=5 moved -> median 2.
        assert_eq!(outs[1].state, SampleState::Boundary);
        assert_eq!(outs[1].shift, 2.0);
        assert!((outs[1].eta - 0.1 * (0.0 + 2.0 + 5.0) / 3.0).abs() < 1e-12);
        assert_eq!(outs[1].p, Vec3::new(1.0, 0.0, 0.0));
        // (3, 0): periodic left (2,0)=2, right (0,0)=0, below (3,1)=7.
        assert_eq!(outs[3].shift, 2.0);
        // (0, 1): left wraps to (3,1)=7, right (1,1)=5, up (0,0)=0,
        // down (0,2) does not move -> median of 0, 5, 7.
        assert_eq!(outs[4].shift, 5.0);
        assert!((outs[4].eta - 0.1 * (7.0 + 5.0 + 0.0 + 8.0) / 4.0).abs() < 1e-12);
        // (1, 2): (0,2), (2,2) do not move, (1,1)=5 moved.
        assert_eq!(outs[9].shift, 5.0);
        // Nothing is left skipped.
        assert!(outs.iter().all(|o| o.state != SampleState::Skipped));

        // A skipped sample whose neighbours all stayed put stays put.
        let mut still = vec![searched(1.0, 0.5, SampleState::Still); 4];
        still[1] = SampleOut {
            state: SampleState::Skipped,
            shift: 9.0,
            ..SampleOut::default()
        };
        fill_skipped(&mut still, 4, 1, &mut fills);
        assert_eq!((still[1].state, still[1].shift), (SampleState::Still, 0.0));
        assert!((still[1].eta - 0.5).abs() < 1e-12);
    }
}
