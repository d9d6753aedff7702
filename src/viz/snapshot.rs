//! Snapshots: a mesh with its input points from three viewpoints.
//!
//! Each view is an orthographic projection. The **camera side** looks from
//! the sensor (the reconstruction's viewpoint, else the frame's origin)
//! toward the object; **side** turns that view 90° about the up axis and
//! **back** 180°, so the back view shows the side the sensor never saw
//! (the membrane's closure of the unseen side, paper §III-D). The up axis
//! is −y when the camera looks mostly along z (a ROS optical frame: x
//! right, y down, z forward), else +z (a ROS body frame). All three views
//! share one scale, set by the meshes, so sizes compare across views and
//! stray outliers do not shrink the object.
//!
//! Triangles (flat-shaded by the angle to the light at the eye), the
//! ground truth (translucent green) and the points (orange) are drawn in one
//! back-to-front order (the painter's algorithm), so the mesh hides the
//! points behind it. The polygons and dots are filled by plotters.

use super::{draw_err, ensure_font, Canvas, VizError, FAMILY};
use crate::cloud::Vec3;
use crate::mesh::TriMesh;
use plotters::prelude::*;
use std::path::Path;

/// Colour of the reconstructed mesh (before shading). Blue dominates every
/// shade of it, which is what the tests count.
pub const MESH_RGB: (u8, u8, u8) = (52, 110, 235);
/// Colour of the input points.
pub const POINT_RGB: (u8, u8, u8) = (245, 130, 20);
/// Colour of the ground-truth mesh (drawn translucent).
pub const TRUTH_RGB: (u8, u8, u8) = (30, 170, 60);
/// Titles of the three views, left to right.
pub const VIEWS: [&str; 3] = ["camera side", "side", "back"];

/// What one snapshot shows.
#[derive(Debug, Clone, Copy)]
pub struct Scene<'a> {
    /// The reconstructed mesh.
    pub mesh: &'a TriMesh,
    /// The input points.
    pub points: &'a [Vec3],
    /// The ground-truth mesh in the same frame, if known.
    pub truth: Option<&'a TriMesh>,
    /// Where the sensor was (default: the frame's origin).
    pub viewpoint: Option<Vec3>,
    /// Caption under the views.
    pub caption: &'a str,
}

/// Picture size: three square-ish panels side by side, a caption below.
const PANEL: u32 = 400;
const TITLE_H: u32 = 28;
const CAPTION_H: u32 = 30;

/// One orthographic view: screen axes `right`, `up` and the viewing
/// direction `forward` (depth grows away from the eye).
#[derive(Debug, Clone, Copy)]
struct View {
    right: Vec3,
    up: Vec3,
    forward: Vec3,
}

impl View {
    fn project(&self, p: &Vec3, c: &Vec3) -> (f64, f64, f64) {
        let d = p - c;
        (d.dot(&self.right), d.dot(&self.up), d.dot(&self.forward))
    }
}

/// The camera-side, side and back views of an object centred at `center`.
fn views(center: &Vec3, viewpoint: Option<Vec3>) -> [View; 3] {
    let eye = viewpoint.unwrap_or_else(Vec3::zeros);
    let forward = (center - eye)
        .try_normalize(1e-12)
        .unwrap_or_else(|| Vec3::new(0.0, 0.0, 1.0));
    let up0 = if forward.z.abs() >= forward.x.abs().max(forward.y.abs()) {
        Vec3::new(0.0, -1.0, 0.0)
    } else {
        Vec3::new(0.0, 0.0, 1.0)
    };
    let up = (up0 - forward * up0.dot(&forward))
        .try_normalize(1e-9)
        .unwrap_or_else(|| forward.cross(&Vec3::x()).normalize());
    let make = |f: Vec3| View {
        right: f.cross(&up),
        up,
        forward: f,
    };
    let camera = make(forward);
    [camera, make(camera.right), make(-forward)]
}

/// One thing to draw, at its depth.
enum Item {
    Triangle([(f64, f64); 3], RGBAColor),
    Dot((f64, f64)),
}

/// Render `scene` as a PNG at `path`.
///
/// # Errors
/// [`VizError::Empty`] when the mesh has no triangles and there are no
/// points; [`VizError::Draw`] / [`VizError::Write`] when drawing or writing fails.
pub fn write_snapshot(scene: &Scene<'_>, path: &Path) -> Result<(), VizError> {
    ensure_font()?;
    let framing: Vec<&Vec3> = if scene.mesh.is_empty() {
        scene.points.iter().collect()
    } else {
        scene
            .mesh
            .vertices
            .iter()
            .chain(scene.truth.iter().flat_map(|t| t.vertices.iter()))
            .collect()
    };
    if framing.is_empty() {
        return Err(VizError::Empty("a snapshot without mesh or points".into()));
    }
    let aabb = crate::cloud::Aabb::from_points(framing.iter().copied());
    let center = aabb.center();
    let radius = framing
        .iter()
        .map(|p| (*p - center).norm())
        .fold(0.0, f64::max)
        .max(1e-9);
    let (w, h) = (3 * PANEL, PANEL + TITLE_H + CAPTION_H);
    let mut canvas = Canvas::new(w, h);
    {
        let root = BitMapBackend::with_buffer(&mut canvas.rgb, (w, h)).into_drawing_area();
        let what = "snapshot";
        root.fill(&WHITE).map_err(draw_err(what))?;
        let (top, bottom) = root.split_vertically(PANEL + TITLE_H);
        let panels = top.split_evenly((1, 3));
        let scale = 0.46 * f64::from(PANEL) / radius;
        for ((panel, view), title) in panels
            .iter()
            .zip(views(&center, scene.viewpoint))
            .zip(VIEWS)
        {
            draw_view(panel, &view, scene, &center, scale, title)?;
        }
        let legend = format!(
            "{}   blue: mesh, orange: input points{}",
            scene.caption,
            if scene.truth.is_some() {
                ", green: ground truth"
            } else {
                ""
            }
        );
        bottom
            .draw(&Text::new(legend, (10, 6), (FAMILY, 16).into_font()))
            .map_err(draw_err(what))?;
        root.present().map_err(draw_err(what))?;
    }
    canvas.save_png(path)
}

/// Draw one view into `panel`: the title, then every item back to front.
fn draw_view<DB: DrawingBackend>(
    panel: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    scene: &Scene<'_>,
    center: &Vec3,
    scale: f64,
    title: &str,
) -> Result<(), VizError> {
    let what = "snapshot view";
    panel
        .draw(&Text::new(title, (10, 6), (FAMILY, 18).into_font()))
        .map_err(draw_err(what))?;
    panel
        .draw(&Rectangle::new(
            [
                (2, TITLE_H as i32),
                (PANEL as i32 - 2, (PANEL + TITLE_H) as i32 - 2),
            ],
            RGBColor(200, 200, 200),
        ))
        .map_err(draw_err(what))?;
    let half = f64::from(PANEL) / 2.0;
    let to_px = |(x, y): (f64, f64)| -> (i32, i32) {
        (
            (half + x * scale).round() as i32,
            (f64::from(TITLE_H) + half - y * scale).round() as i32,
        )
    };
    let mut items = depth_sorted_items(view, scene, center);
    let inside = |(x, y): (i32, i32)| {
        x > 2 && x < PANEL as i32 - 2 && y > TITLE_H as i32 && y < (PANEL + TITLE_H) as i32 - 2
    };
    for (_, item) in items.drain(..) {
        match item {
            Item::Triangle(corners, colour) => {
                let px: Vec<(i32, i32)> = corners.iter().map(|c| to_px(*c)).collect();
                if px.iter().any(|p| !inside(*p)) {
                    continue;
                }
                panel
                    .draw(&Polygon::new(px, colour.filled()))
                    .map_err(draw_err(what))?;
            }
            Item::Dot(p) => {
                let p = to_px(p);
                if inside(p) {
                    panel
                        .draw(&Circle::new(
                            p,
                            1,
                            RGBColor(POINT_RGB.0, POINT_RGB.1, POINT_RGB.2).filled(),
                        ))
                        .map_err(draw_err(what))?;
                }
            }
        }
    }
    Ok(())
}

/// Every triangle of the mesh and the truth, and every point, projected
/// and sorted far to near.
fn depth_sorted_items(view: &View, scene: &Scene<'_>, center: &Vec3) -> Vec<(f64, Item)> {
    let mut items = Vec::with_capacity(
        scene.mesh.triangles.len()
            + scene.points.len()
            + scene.truth.map_or(0, |t| t.triangles.len()),
    );
    push_triangles(&mut items, view, scene.mesh, center, MESH_RGB, 1.0);
    if let Some(t) = scene.truth {
        push_triangles(&mut items, view, t, center, TRUTH_RGB, 0.18);
    }
    for p in scene.points {
        let (x, y, d) = view.project(p, center);
        items.push((d, Item::Dot((x, y))));
    }
    items.sort_by(|a, b| b.0.total_cmp(&a.0));
    items
}

/// Project and shade the triangles of `mesh` in colour `rgb` with opacity `alpha`.
fn push_triangles(
    items: &mut Vec<(f64, Item)>,
    view: &View,
    mesh: &TriMesh,
    center: &Vec3,
    rgb: (u8, u8, u8),
    alpha: f64,
) {
    // Light from the eye, a little from the upper left.
    let light = (-view.forward + 0.35 * view.up - 0.25 * view.right).normalize();
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        let Some(n) = (b - a).cross(&(c - a)).try_normalize(1e-30) else {
            continue;
        };
        let shade = 0.35 + 0.65 * n.dot(&light).abs();
        let tint = |v: u8| (f64::from(v) * shade).round().clamp(0.0, 255.0) as u8;
        let colour = RGBAColor(tint(rgb.0), tint(rgb.1), tint(rgb.2), alpha);
        let (pa, pb, pc) = (
            view.project(&a, center),
            view.project(&b, center),
            view.project(&c, center),
        );
        let depth = (pa.2 + pb.2 + pc.2) / 3.0;
        items.push((
            depth,
            Item::Triangle([(pa.0, pa.1), (pb.0, pb.1), (pc.0, pc.1)], colour),
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optical_frame_views_are_right_handed_and_turn_about_minus_y() {
        let [cam, side, back] = views(&Vec3::new(0.0, 0.0, 1.0), None);
        assert!((cam.right - Vec3::x()).norm() < 1e-12, "{:?}", cam.right);
        assert!((cam.up + Vec3::y()).norm() < 1e-12);
        assert!((side.forward - Vec3::x()).norm() < 1e-12);
        assert!((back.forward + Vec3::z()).norm() < 1e-12);
    }

    #[test]
    fn body_frame_views_keep_z_up() {
        let [cam, ..] = views(&Vec3::new(2.0, 0.1, 0.0), None);
        assert!((cam.up - Vec3::z()).norm() < 1e-12, "{:?}", cam.up);
    }
}
