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
//!
//! The occluded-back smoothing of warm-started single views (key
//! `regularize.warm_back_smoothing`) was removed (issue 19, item 4): switched
//! off, it changed no figure of `sepmem bench --only ablation-mechanisms`
//! by more than 0.0008 (`docs/ablation-mechanisms.md`), and the replay that
//! had justified it is not committed.

use super::config::RegularizeConfig;
use super::step::{insertion_sort_by, SampleOut, SampleState};

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

/// The shifts the refit follows: the median-filtered (or raw) shifts, then
/// pole tension (whole objects only: the unseen back of a single view,
/// `single_view`, is held where it is).
pub fn shifts(cfg: &RegularizeConfig, s: Samples<'_>, single_view: bool, out: &mut Vec<f64>) {
    if cfg.median_filter {
        median_filter(s, out);
    } else {
        out.clear();
        out.extend(s.outs.iter().map(|o| o.shift));
    }
    if let (Some(t), false) = (&cfg.pole_tension, single_view) {
        pole_tension(s, t.strength, t.rows, out);
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
