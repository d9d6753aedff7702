//! Markdown rendering of a [`super::BenchReport`]: one table per
//! section, laid out like the paper's Table 1 (Chamfer-L1, F-score, normal
//! consistency, time).

use super::mechanisms::Mechanisms;
use super::{BenchReport, RunResult, Summary};
use std::fmt::Write;

fn f3(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "-".into()
    }
}

fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

fn scores_cells(r: &RunResult) -> String {
    match (&r.scores, &r.error) {
        (Some(s), _) => format!(
            "{} | {} | {}",
            f4(s.chamfer_l1),
            f3(s.fscore),
            f3(s.normal_consistency)
        ),
        (None, Some(e)) => format!("failed: {} | - | -", e.replace('|', "/")),
        (None, None) => "- | - | -".into(),
    }
}

fn summary_table(out: &mut String, title: &str, rows: &[Summary]) {
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(out, "\n**{title}**\n");
    let _ = writeln!(
        out,
        "| condition | rows | failed | Chamfer-L1 | F-score | NC | time (ms) |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|");
    for s in rows {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {:.0} |",
            s.group,
            s.rows,
            s.failed,
            f4(s.chamfer_l1),
            f3(s.fscore),
            f3(s.normal_consistency),
            s.time_ms
        );
    }
}

fn signed(v: f64) -> String {
    if v.is_finite() {
        format!("{v:+.4}")
    } else {
        "-".into()
    }
}

fn mechanisms_table(out: &mut String, m: &Mechanisms) {
    let _ = writeln!(
        out,
        "\n## Mechanism ablation: ΔF = F(switched) − F(baseline)\n\nTable 1: {} shapes ({}), {} points, the paper's four conditions (genus 0, genus > 0) and the non-uniform one; sweep: six σ; replays: {} synth sequences of {} frames ({}). `≤ {}`: no |ΔF| above {} (removal candidate).\n",
        m.table1_shapes.len(),
        m.table1_shapes.join(", "),
        m.table1_points,
        m.replays.len(),
        m.replay_frames,
        m.replays.join(", "),
        m.threshold,
        m.threshold
    );
    let _ = writeln!(
        out,
        "| switch | ΔF Table 1 genus 0 | ΔF Table 1 genus > 0 | ΔF Table 1 non-uniform | ΔF sweep | ΔF replays | failed | ≤ {} |",
        m.threshold
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|");
    for r in &m.rows {
        let cells: Vec<String> = if r.switch == "baseline" {
            r.figures
                .values()
                .iter()
                .map(|v| format!("F {}", f4(*v)))
                .collect()
        } else {
            r.delta.values().iter().map(|v| signed(*v)).collect()
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} |",
            r.switch,
            cells.join(" | "),
            r.failed,
            if r.switch == "baseline" {
                ""
            } else if r.below_threshold {
                "yes"
            } else {
                "no"
            }
        );
    }
}

/// Render the whole report as Markdown.
pub fn render(rep: &BenchReport) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# sepmem bench{}\n\nseed {}, membrane threads {} (0 = all cores), total {:.1} s",
        if rep.quick { " (--quick)" } else { "" },
        rep.seed,
        rep.threads,
        rep.total_s
    );
    if let Some(t) = &rep.table1 {
        let _ = writeln!(
            out,
            "\n## Table 1: {} points per cloud (F-score at 0.01, unit longest edge)\n",
            t.points
        );
        let _ = writeln!(out, "| shape | genus | condition | points | Chamfer-L1 | F-score | NC | time (ms) | iters | watertight |");
        let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|");
        for r in &t.rows {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {:.0} | {} | {} |",
                r.shape,
                r.genus,
                r.condition.name(),
                r.points,
                scores_cells(&r.run),
                r.run.time_ms,
                r.run.iterations,
                if r.run.watertight { "yes" } else { "NO" }
            );
        }
        summary_table(
            &mut out,
            "Genus-0 shapes: mean per condition and overall",
            &t.genus0,
        );
        summary_table(
            &mut out,
            "Genus > 0 shapes (tunnels): mean per condition and overall",
            &t.genus_pos,
        );
    }
    if let Some(s) = &rep.sweep {
        let _ = writeln!(
            out,
            "\n## Sphere sweep: 1,000 points + 1,000 duplicates perturbed with σ\n"
        );
        let _ = writeln!(out, "| σ | Chamfer-L1 | F-score | NC | time (ms) |");
        let _ = writeln!(out, "|---|---|---|---|---|");
        for r in s {
            let _ = writeln!(
                out,
                "| {} | {} | {:.0} |",
                r.sigma,
                scores_cells(&r.run),
                r.run.time_ms
            );
        }
    }
    if let Some(a) = &rep.adaptive {
        let _ = writeln!(out, "\n## Static vs adaptive membrane on `{}`\n", a.shape);
        let _ = writeln!(
            out,
            "| mode | final grid | iterations | Chamfer-L1 | F-score | NC | total time (ms) |"
        );
        let _ = writeln!(out, "|---|---|---|---|---|---|---|");
        for r in &a.rows {
            let _ = writeln!(
                out,
                "| {} | {}x{} | {} | {} | {:.0} |",
                r.mode,
                r.run.grid[0],
                r.run.grid[1],
                r.run.iterations,
                scores_cells(&r.run),
                r.run.time_ms
            );
        }
        let _ = writeln!(
            out,
            "\nChamfer-L1 of the surface returned after k iterations:\n"
        );
        for r in &a.rows {
            let cells: Vec<String> = r
                .chamfer_per_iteration
                .iter()
                .map(|(k, c)| format!("{k}: {}", f4(*c)))
                .collect();
            let _ = writeln!(out, "- {}: {}", r.mode, cells.join(", "));
        }
    }
    if let Some(ab) = &rep.ablation {
        let _ = writeln!(
            out,
            "\n## Attribute ablation: white object points, dark random-coloured outliers\n"
        );
        let _ = writeln!(
            out,
            "| shape | σ | features | Chamfer-L1 | F-score | NC | time (ms) |"
        );
        let _ = writeln!(out, "|---|---|---|---|---|---|---|");
        for r in ab {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {:.0} |",
                r.shape,
                r.sigma,
                r.features,
                scores_cells(&r.run),
                r.run.time_ms
            );
        }
    }
    if let Some(real) = &rep.real {
        let _ = writeln!(out, "\n## Real scans\n");
        let _ = writeln!(out, "| input | reference | points | Chamfer-L1 | F-score | NC | η_g | iters | time (ms) | watertight |");
        let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|");
        for r in real {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {:.0} | {} |",
                r.input,
                r.reference.as_deref().unwrap_or("none"),
                r.points,
                scores_cells(&r.run),
                f3(r.run.eta_final),
                r.run.iterations,
                r.run.time_ms,
                if r.run.watertight { "yes" } else { "NO" }
            );
        }
    }
    if let Some(s) = &rep.speed {
        let _ = writeln!(
            out,
            "\n## Speed: cold reconstruction, one thread, `{}` with {} points, {} repeats\n\nmedian {:.1} ms (min {:.1}, max {:.1}), {} iterations\n",
            s.shape, s.points, s.repeats, s.median_ms, s.min_ms, s.max_ms, s.iterations
        );
        let _ = writeln!(out, "| phase | median (ms) |");
        let _ = writeln!(out, "|---|---|");
        for (p, ms) in &s.phases {
            let _ = writeln!(out, "| {p} | {ms:.1} |");
        }
        if let Some(w) = &s.warm {
            let _ = writeln!(
                out,
                "\n### Warm-started frames (object moved by 1 %, at most {} iterations), {} frames\n\nmedian {:.1} ms, p95 {:.1} ms, max {:.1} ms, median {:.1} iterations, F-score {:.3}\n",
                w.max_iterations, w.frames, w.median_ms, w.p95_ms, w.max_ms, w.iterations, w.fscore
            );
            let _ = writeln!(out, "| phase | median (ms) |");
            let _ = writeln!(out, "|---|---|");
            for (p, ms) in &w.phases {
                let _ = writeln!(out, "| {p} | {ms:.1} |");
            }
        }
    }
    if let Some(m) = &rep.mechanisms {
        mechanisms_table(&mut out, m);
    }
    if !rep.skipped.is_empty() {
        let _ = writeln!(out, "\n## Skipped\n");
        for s in &rep.skipped {
            let _ = writeln!(out, "- SKIPPED {}: {}", s.what, s.reason);
        }
    }
    out
}
