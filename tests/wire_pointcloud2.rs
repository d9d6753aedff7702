//! Fuzzing the PointCloud2 path with proptest: random layouts and random
//! byte mutations of valid CDR must give a value or a typed error, never a
//! panic, and valid random clouds must decode to exactly what was encoded.
#![allow(clippy::unwrap_used)]

mod common;

use proptest::prelude::*;
use sepmem::wire::msgs::{Header, PointCloud2, PointField, Time};
use sepmem::wire::pointcloud2::{decode_pointcloud2, encode_pointcloud2, WireConfig};
use sepmem::wire::{decode, encode};
use sepmem::{PointCloud, Vec3};

fn limits() -> WireConfig {
    WireConfig {
        max_points: 100_000,
        max_bytes: 1 << 22,
    }
}

fn arb_field() -> impl Strategy<Value = PointField> {
    (
        prop::sample::select(vec![
            "x",
            "y",
            "z",
            "rgb",
            "rgba",
            "intensity",
            "label",
            "r",
            "n",
        ]),
        0u32..40,
        0u8..11,
        0u32..4,
    )
        .prop_map(|(name, offset, datatype, count)| PointField {
            name: name.to_string(),
            offset,
            datatype,
            count,
        })
}

fn arb_msg() -> impl Strategy<Value = PointCloud2> {
    (
        prop::collection::vec(arb_field(), 0..7),
        0u32..6,
        0u32..12,
        0u32..48,
        0u32..400,
        any::<bool>(),
        prop::collection::vec(any::<u8>(), 0..1200),
    )
        .prop_map(
            |(fields, height, width, point_step, row_step, be, data)| PointCloud2 {
                header: Header {
                    stamp: Time { sec: 1, nanosec: 2 },
                    frame_id: "f".into(),
                },
                height,
                width,
                fields,
                is_bigendian: be,
                point_step,
                row_step,
                data,
                is_dense: false,
            },
        )
}

fn valid_xyz(n: usize) -> PointCloud2 {
    let c = PointCloud::from_points(
        (0..n)
            .map(|i| Vec3::new(i as f64, -(i as f64) * 0.5, 2.0))
            .collect(),
    );
    encode_pointcloud2(&c, Header::default())
}

/// 2000 cases per property in the test suite; set `SEPMEM_FUZZ_CASES` for a
/// longer fuzzing session.
fn fuzz_config() -> ProptestConfig {
    let cases = std::env::var("SEPMEM_FUZZ_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(2000);
    ProptestConfig {
        cases,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(fuzz_config())]

    /// Random layouts: no panic, and whatever decodes respects the counts.
    #[test]
    fn random_layouts_never_panic(msg in arb_msg()) {
        if let Ok(d) = decode_pointcloud2(&msg, &limits()) {
            prop_assert_eq!(d.cloud.len() + d.dropped_non_finite, d.points_in);
            prop_assert_eq!(d.points_in, (msg.width * msg.height) as usize);
            for a in &d.cloud.attributes {
                prop_assert_eq!(a.values.len(), d.cloud.len());
            }
            prop_assert!(d.cloud.points.iter().all(|p| p.iter().all(|c| c.is_finite())));
        }
        // And through CDR.
        let bytes = encode(&msg).unwrap();
        let back: PointCloud2 = decode(&bytes).unwrap();
        prop_assert_eq!(back, msg);
    }

    /// Random byte mutations and truncations of a valid message's CDR.
    #[test]
    fn mutated_cdr_never_panics(
        n in 0usize..20,
        muts in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = encode(&valid_xyz(n)).unwrap();
        for (i, v) in muts {
            let i = i.index(bytes.len());
            bytes[i] = v;
        }
        let len = cut.index(bytes.len() + 1);
        for b in [&bytes[..], &bytes[..len]] {
            if let Ok(msg) = decode::<PointCloud2>(b) {
                let _ = decode_pointcloud2(&msg, &limits());
            }
        }
    }

    /// Valid random clouds round-trip exactly (f32 positions).
    #[test]
    fn valid_clouds_round_trip(pts in prop::collection::vec((-1e3f32..1e3, -1e3f32..1e3, -1e3f32..1e3), 0..200)) {
        let c = PointCloud::from_points(pts.iter().map(|&(x, y, z)| Vec3::new(x.into(), y.into(), z.into())).collect());
        let msg = encode_pointcloud2(&c, Header::default());
        let d = decode_pointcloud2(&decode(&encode(&msg).unwrap()).unwrap(), &limits()).unwrap();
        prop_assert_eq!(d.cloud.points, c.points);
    }
}
