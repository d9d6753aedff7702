//! Output messages of one processed frame: sepmem's stamped mesh, the
//! per-frame diagnostics, and RViz/Foxglove TRIANGLE_LIST markers.
//!
//! Every mesh carries the verdict on its surface ([`Quality`], the
//! `quality` field of `SurfaceMesh`): under CPU load the demo once
//! published the octagon start surface of a cold start after 0 iterations
//! as a cereal box, and nothing in the mesh or marker said so. A surface
//! that is not fitted is drawn in one colour that says why (grey held,
//! orange unconverged, red unfitted) instead of the separability ramp.
//!
//! The mesh carries the per-vertex separability `η*` found at each sample
//! (paper Eq. 7 / Eq. 9) and the global separability η_g, the mean of the
//! per-sample maxima (paper §III-F step 1). Marker colours map the vertex
//! separability to a blue (low) → yellow (high) ramp.

use super::objects::Quality;
use super::{FrameResult, StartPath};
use crate::cloud::{Attribute, PointCloud};
use crate::wire::convert::{delete_all_marker, to_shape_mesh, to_triangle_list_marker};
use crate::wire::msgs::{
    ColorRGBA, FrameDiagnostics, Header, Marker, MarkerArray, PointCloud2, SurfaceMesh,
};
use crate::wire::pointcloud2::encode_pointcloud2;

/// Name of the per-vertex separability channel in membrane meshes.
pub const SEPARABILITY: &str = "separability";

/// sepmem's stamped mesh message for a frame, with the frame's own verdict
/// ([`Quality::of_frame`]; the node refines it with the object's history).
pub fn surface_mesh(r: &FrameResult, header: &Header) -> SurfaceMesh {
    let rec = &r.reconstruction;
    let mesh = &rec.mesh;
    let geometry = to_shape_mesh(mesh);
    SurfaceMesh {
        header: header.clone(),
        stream_id: r.stream.to_string(),
        object_id: r.stream.label.map_or(0, |l| u32::try_from(l).unwrap_or(0)),
        vertices: geometry.vertices,
        triangles: geometry.triangles,
        vertex_separability: mesh
            .scalar(SEPARABILITY)
            .map(<[f32]>::to_vec)
            .unwrap_or_default(),
        global_separability: rec.report.eta_final as f32,
        grid_m: rec.report.grid[0] as u32,
        grid_l: rec.report.grid[1] as u32,
        iterations: r.iterations as u32,
        warm_start: r.path == StartPath::Warm,
        start_reason: r.reason.to_string(),
        stop_reason: rec.report.stop.to_string(),
        quality: Quality::of_frame(r).code(),
    }
}

/// The per-frame diagnostics message.
pub fn frame_diagnostics(
    r: &FrameResult,
    header: &Header,
    points_in: usize,
    dropped: usize,
) -> FrameDiagnostics {
    let rep = &r.reconstruction.report;
    FrameDiagnostics {
        header: header.clone(),
        stream_id: r.stream.to_string(),
        frame_index: r.frame,
        points_in: points_in as u32,
        points_used: rep.points_used as u32,
        points_dropped: (dropped
            + rep.points_non_finite
            + rep.points_duplicate
            + rep.points_detached
            + r.flying.dropped
            + rep.points_outliers) as u32,
        iterations: r.iterations as u32,
        global_separability: rep.eta_final as f32,
        latency_ms: r.latency_ms as f32,
        warm_start: r.path == StartPath::Warm,
        start_reason: r.reason.to_string(),
        stop_reason: rep.stop.to_string(),
    }
}

/// A stable marker id for a stream (FNV-1a of its key, non-negative).
pub fn marker_id(stream: &str) -> i32 {
    let mut h: u32 = 0x811c_9dc5;
    for b in stream.bytes() {
        h ^= u32::from(b);
        h = h.wrapping_mul(0x0100_0193);
    }
    (h & 0x7fff_ffff) as i32
}

/// Blue → yellow colour for a separability value in [0, 1].
fn ramp(s: f32) -> ColorRGBA {
    let s = s.clamp(0.0, 1.0);
    ColorRGBA {
        r: s,
        g: 0.3 + 0.6 * s,
        b: 1.0 - s,
        a: 1.0,
    }
}

/// One TRIANGLE_LIST marker for a frame's mesh (namespace `ns`), coloured
/// per vertex by its separability when it is fitted, else in the colour of
/// its verdict ([`Quality::marker_color`]).
pub fn triangle_marker(r: &FrameResult, header: &Header, ns: &str) -> Marker {
    let mut m = separability_marker(r, header, ns);
    Quality::of_frame(r).paint(&mut m);
    m
}

/// [`triangle_marker`] coloured by separability whatever the verdict.
pub fn separability_marker(r: &FrameResult, header: &Header, ns: &str) -> Marker {
    let mesh = &r.reconstruction.mesh;
    let base = ColorRGBA {
        r: 0.2,
        g: 0.7,
        b: 0.9,
        a: 1.0,
    };
    let mut marker = to_triangle_list_marker(
        mesh,
        header.clone(),
        ns,
        marker_id(&r.stream.to_string()),
        base,
    );
    if let Some(sep) = mesh.scalar(SEPARABILITY) {
        marker.colors = mesh
            .triangles
            .iter()
            .flat_map(|t| t.map(|i| ramp(sep.get(i as usize).copied().unwrap_or(0.0))))
            .collect();
    }
    marker
}

/// A marker array that first clears the namespace (DELETEALL, so vanished
/// objects disappear) and then adds one marker per current object.
pub fn marker_array(results: &[&FrameResult], header: &Header, ns: &str) -> MarkerArray {
    cleared_markers(
        results
            .iter()
            .map(|r| triangle_marker(r, header, ns))
            .collect(),
        header,
        ns,
    )
}

/// A DELETEALL marker for namespace `ns`, then `markers`.
pub fn cleared_markers(markers: Vec<Marker>, header: &Header, ns: &str) -> MarkerArray {
    let mut clear = delete_all_marker(header.clone());
    clear.ns = ns.to_string();
    let mut all = Vec::with_capacity(markers.len() + 1);
    all.push(clear);
    all.extend(markers);
    MarkerArray { markers: all }
}

/// The fused models of a frame's objects (`pipeline.model`) as one
/// PointCloud2 in the input's frame: `x y z` and, per point, its object's
/// label in channel `label` (0 for an unlabelled stream). `None` when no
/// object keeps a model.
pub fn model_cloud(results: &[&FrameResult], header: &Header, label: &str) -> Option<PointCloud2> {
    let with_model: Vec<(&Vec<crate::cloud::Vec3>, f32)> = results
        .iter()
        .filter_map(|r| Some((r.model.as_ref()?, r.stream.label.unwrap_or(0) as f32)))
        .collect();
    if with_model.is_empty() {
        return None;
    }
    let n = with_model.iter().map(|(m, _)| m.len()).sum();
    let (mut points, mut labels) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for (m, l) in with_model {
        points.extend_from_slice(m);
        labels.extend(std::iter::repeat_n(l, m.len()));
    }
    let cloud = PointCloud {
        points,
        attributes: vec![Attribute {
            name: label.to_string(),
            values: labels,
        }],
    };
    Some(encode_pointcloud2(&cloud, header.clone()))
}
