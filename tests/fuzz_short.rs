//! The stable short fuzz pass that CI runs inside `cargo test --release`
//! (CI machines need not have cargo-fuzz): every decoder of
//! `tests/fuzz/src/lib.rs` (PointCloud2/CDR, PLY, PCD in its three
//! encodings, XYZ, OBJ, the MCAP bag reader) runs over the committed seed
//! corpus `tests/fuzz/corpus/TARGET/` and over [`MUTATIONS`] seeded random
//! mutations of it per target (`SEPMEM_FUZZ_MUTATIONS` sets the count). A
//! panic fails the test and names the target
//! and the input (written to a temporary file for replay).
//!
//! The long runs (≥ 1 M executions per target) use libFuzzer through
//! cargo-fuzz on nightly: `cargo +nightly fuzz run --fuzz-dir tests/fuzz
//! TARGET tests/fuzz/corpus/TARGET -- -runs=1000000`.
//!
//! `write_seed_corpus` (ignored) regenerates the seeds;
//! `replay_corpus_timing` (ignored) replays a grown corpus and counts the
//! inputs slower than 100 ms per MB (1 ms floor), without asserting time.
#![allow(clippy::unwrap_used)]

#[path = "fuzz/src/lib.rs"]
mod targets;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The system allocator, remembering each thread's largest single
/// request: a decoder must not allocate what an input's length field claims.
struct Largest;

thread_local! {
    static LARGEST: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn note(size: usize) {
    // `try_with`: nothing to note while the thread is being torn down.
    let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
}

#[allow(unsafe_code)]
// SAFETY: forwards every call to the system allocator unchanged.
unsafe impl GlobalAlloc for Largest {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: the caller's contract is passed on as is.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Largest = Largest;

/// The inputs libFuzzer found (`tests/fuzz/findings/`, each named after its
/// target) are read with no allocation larger than 64 MiB: before the fix,
/// a 4.7 kB bag made the MCAP reader reserve 2.8 GB for one topic string.
#[test]
fn findings_never_allocate_what_a_length_field_claims() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/findings");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let Some(target) = targets::TARGETS
            .iter()
            .find(|t| name.starts_with(&format!("{t}-")))
        else {
            continue;
        };
        let data = std::fs::read(&path).unwrap();
        LARGEST.with(|l| l.set(0));
        assert!(targets::run(target, &data));
        let largest = LARGEST.with(std::cell::Cell::get);
        println!(
            "{name}: {} bytes, largest allocation {largest} bytes",
            data.len()
        );
        assert!(largest < 64 << 20, "{name}: allocated {largest} bytes");
        checked += 1;
    }
    assert!(checked >= 1, "no findings in {}", dir.display());
}

/// Seeded mutations per target and run (6 targets: 24,000 decoder calls).
const MUTATIONS: usize = 4000;

fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz/corpus")
        .join(target)
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file());
    v.sort();
    v
}

/// xorshift64*: a small deterministic generator for the mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const BYTES: [u8; 10] = [0, 0xff, 0x7f, 0x80, b'0', b'9', b'\n', b' ', b'-', b'.'];
const WORDS: [u32; 7] = [
    0,
    1,
    u32::MAX,
    0x7fff_ffff,
    0x8000_0000,
    4_000_000_000,
    65_536,
];
const NUMBERS: [&str; 8] = [
    "0",
    "-1",
    "4294967295",
    "1e308",
    "nan",
    "99999999999999999999",
    "100000",
    "-0",
];

/// One to four random edits of `seed`: bit flips, interesting bytes and
/// 32-bit words, deleted / duplicated ranges, truncation, and numbers in
/// text replaced by extreme ones.
fn mutate(seed: &[u8], rng: &mut Rng, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(seed);
    for _ in 0..1 + rng.below(4) {
        let len = out.len();
        let at = rng.below(len);
        match rng.below(7) {
            0 if len > 0 => out[at] ^= 1 << rng.below(8),
            1 if len > 0 => out[at] = BYTES[rng.below(BYTES.len())],
            2 if len >= 4 => {
                let at = at.min(len - 4);
                let w = WORDS[rng.below(WORDS.len())].to_le_bytes();
                out[at..at + 4].copy_from_slice(&w);
            }
            3 => {
                let end = (at + 1 + rng.below(64)).min(len);
                out.drain(at..end);
            }
            4 if len > 0 && len < 1 << 20 => {
                let end = (at + 1 + rng.below(256)).min(len);
                let piece = out[at..end].to_vec();
                let to = rng.below(len);
                out.splice(to..to, piece);
            }
            5 => out.truncate(at),
            _ => {
                let Some(start) = (at..len).find(|&i| out[i].is_ascii_digit()) else {
                    continue;
                };
                let end = (start..len)
                    .find(|&i| !out[i].is_ascii_digit())
                    .unwrap_or(len);
                let n = NUMBERS[rng.below(NUMBERS.len())].as_bytes().to_vec();
                out.splice(start..end, n);
            }
        }
    }
}

/// Run `target` on `data`; on a panic, keep the input and fail naming it.
fn run_or_report(target: &str, data: &[u8], what: &str) {
    let r = std::panic::catch_unwind(|| targets::run(target, data));
    match r {
        Ok(true) => {}
        Ok(false) => panic!("unknown target {target}"),
        Err(_) => {
            let keep = std::env::temp_dir().join(format!("sepmem-fuzz-{target}-crash.bin"));
            let _ = std::fs::write(&keep, data);
            panic!(
                "{target} panicked on {what} ({} bytes, kept in {})",
                data.len(),
                keep.display()
            );
        }
    }
}

#[test]
fn every_decoder_survives_the_corpus_and_seeded_mutations() {
    // SEPMEM_FUZZ_MUTATIONS=1000000 makes this the long stable pass.
    let mutations = std::env::var("SEPMEM_FUZZ_MUTATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(MUTATIONS);
    let mut out = Vec::new();
    for (k, target) in targets::TARGETS.iter().enumerate() {
        let seeds: Vec<Vec<u8>> = files(&corpus_dir(target))
            .iter()
            .map(|p| std::fs::read(p).unwrap())
            .collect();
        assert!(
            seeds.len() >= 3,
            "{target}: the committed corpus has {} seeds",
            seeds.len()
        );
        for (i, s) in seeds.iter().enumerate() {
            run_or_report(target, s, &format!("seed {i}"));
        }
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ (k as u64 + 1));
        let (mut slow, t0) = (0usize, Instant::now());
        for m in 0..mutations {
            let seed = &seeds[rng.below(seeds.len())];
            mutate(seed, &mut rng, &mut out);
            let t = Instant::now();
            run_or_report(target, &out, &format!("mutation {m}"));
            if t.elapsed().as_secs_f64() > slow_limit_s(out.len()) && is_slow(target, &out) {
                slow += 1;
                let keep = std::env::temp_dir().join(format!("sepmem-fuzz-{target}-slow-{m}.bin"));
                let _ = std::fs::write(&keep, &out);
                println!(
                    "slow {target}: mutation {m}, {} bytes, kept in {}",
                    out.len(),
                    keep.display()
                );
            }
        }
        // Timing is reported, never asserted (shared machines are noisy).
        println!(
            "{target}: {} seeds + {mutations} mutations in {:.1} s, 0 panics, {slow} slower than 100 ms/MB (1 ms floor) on the best of 5 runs",
            seeds.len(),
            t0.elapsed().as_secs_f64()
        );
    }
}

/// Whether `data` is slow on its fastest of five runs: a single slow run on
/// a shared machine is mostly a preemption, not the decoder.
fn is_slow(target: &str, data: &[u8]) -> bool {
    let best = (0..5)
        .map(|_| {
            let t = Instant::now();
            targets::run(target, data);
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    best > slow_limit_s(data.len())
}

/// 100 ms per MB of input, with a 1 ms floor: the issue's bound on a slow input.
fn slow_limit_s(bytes: usize) -> f64 {
    (0.1 * bytes as f64 / 1e6).max(1e-3)
}

/// Replay every file under `$SEPMEM_FUZZ_CORPUS/TARGET/` (a libFuzzer-grown
/// corpus) and print, per target, the inputs and how many took longer than
/// 100 ms per MB of input (with a 1 ms floor). Prints a SKIPPED line without
/// the variable. Timing is reported, never asserted.
#[test]
#[ignore = "measurement: set SEPMEM_FUZZ_CORPUS and run with --ignored"]
fn replay_corpus_timing() {
    let Some(root) = std::env::var_os("SEPMEM_FUZZ_CORPUS") else {
        println!("SKIPPED replay_corpus_timing: SEPMEM_FUZZ_CORPUS is not set");
        return;
    };
    for target in targets::TARGETS {
        let (mut n, mut slow, mut worst) = (0usize, 0usize, 0.0f64);
        for p in files(&Path::new(&root).join(target)) {
            let data = std::fs::read(&p).unwrap();
            let t = Instant::now();
            run_or_report(target, &data, &p.display().to_string());
            let s = t.elapsed().as_secs_f64();
            let limit = slow_limit_s(data.len());
            n += 1;
            if s > limit {
                slow += 1;
                println!(
                    "slow {target}: {} ({} bytes, {:.1} ms)",
                    p.display(),
                    data.len(),
                    s * 1e3
                );
            }
            worst = worst.max(s * 1e6 / data.len().max(1) as f64);
        }
        println!("{target}: {n} inputs, {slow} slower than 100 ms/MB (1 ms floor), worst {worst:.1} µs per byte");
    }
}

/// Write the seed corpus: small valid files of every format and encoding.
#[test]
#[ignore = "generator: run with --ignored to rewrite tests/fuzz/corpus"]
fn write_seed_corpus() {
    for (target, seeds) in seeds::all() {
        let dir = corpus_dir(target);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in seeds {
            std::fs::write(dir.join(name), bytes).unwrap();
        }
    }
}

mod seeds {
    use sepmem::cloud::{PointCloud, Vec3};
    use sepmem::wire::msgs::{Header, PointCloud2, PointField};
    use std::path::Path;

    type Seeds = Vec<(&'static str, Vec<u8>)>;

    fn cloud(n: usize) -> PointCloud {
        let mut c = PointCloud::from_points(
            (0..n)
                .map(|i| {
                    let t = i as f64 * 0.7;
                    Vec3::new(t.cos(), t.sin(), 0.1 * t)
                })
                .collect(),
        );
        let ramp: Vec<f32> = (0..n).map(|i| i as f32 / n as f32).collect();
        for ch in ["r", "g", "b", "intensity"] {
            c.set_attribute(ch, ramp.clone()).unwrap();
        }
        c.set_attribute("label", (0..n).map(|i| (i % 3) as f32).collect())
            .unwrap();
        c
    }

    fn tetra() -> sepmem::mesh::TriMesh {
        sepmem::mesh::TriMesh {
            vertex_scalars: vec![("q".into(), vec![0.0, 1.0, 2.0, 3.0])],
            ..sepmem::mesh::TriMesh::unit_tetrahedron()
        }
    }

    fn pointcloud2() -> Seeds {
        let enc = |m: &PointCloud2| sepmem::wire::encode(m).unwrap();
        let plain = sepmem::wire::pointcloud2::encode_pointcloud2(&cloud(6), Header::default());
        let mut organised =
            sepmem::wire::pointcloud2::encode_pointcloud2(&cloud(4), Header::default());
        organised.height = 2;
        organised.width = 2;
        organised.row_step = 2 * organised.point_step;
        let f = PointField::new;
        let wide = PointCloud2 {
            height: 1,
            width: 2,
            fields: vec![
                f("x", 0, PointField::FLOAT64, 1),
                f("y", 8, PointField::FLOAT64, 1),
                f("z", 16, PointField::FLOAT64, 1),
                f("desc", 24, PointField::UINT8, 4),
            ],
            is_bigendian: true,
            point_step: 28,
            row_step: 56,
            data: (0..56u8).collect(),
            ..Default::default()
        };
        vec![
            ("plain.cdr", enc(&plain)),
            ("organised.cdr", enc(&organised)),
            ("f64_be_count4.cdr", enc(&wide)),
            ("empty.cdr", enc(&PointCloud2::default())),
        ]
    }

    fn ply() -> Seeds {
        let p = Path::new("seed.ply");
        let colours = [[255u8, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]];
        vec![
            ("mesh_le.ply", sepmem::io::ply::encode_mesh(&tetra(), Some(&colours), p).unwrap()),
            ("cloud_le.ply", sepmem::io::ply::encode_cloud(&cloud(5), p).unwrap()),
            ("ascii.ply", b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0 255\n1 0 0 0\n1 1 0 7\n0 1 0 9\n3 0 1 2\n4 0 1 2 3\n".to_vec()),
            ("be_double.ply", {
                let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nproperty short q\nend_header\n".to_vec();
                for (v, q) in [([1.5f64, -2.0, 3.25], -7i16), ([0.0, 1e-3, 1e6], 300)] {
                    for c in v {
                        b.extend_from_slice(&c.to_be_bytes());
                    }
                    b.extend_from_slice(&q.to_be_bytes());
                }
                b
            }),
        ]
    }

    fn pcd() -> Seeds {
        vec![
            ("binary.pcd", sepmem::io::pcd::encode_cloud(&cloud(5), false)),
            ("compressed.pcd", sepmem::io::pcd::encode_cloud(&cloud(5), true)),
            ("ascii.pcd", b"VERSION .7\nFIELDS x y z rgb label\nSIZE 4 4 4 4 4\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA ascii\n1 2 3 4.2e-38 7\nnan nan nan 0 0\n4 5 6 4.2e-38 8\n0 0 0 0 9\n".to_vec()),
            ("ascii_count.pcd", b"FIELDS x y z h\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 3\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3 4 5 6\n".to_vec()),
        ]
    }

    fn text() -> (Seeds, Seeds) {
        let xyz = vec![
            ("plain.xyz", b"# c\n1 2 3 9\n4,5,6,8\nnan 0 0 7\n".to_vec()),
            (
                "header.xyz",
                b"x y z red green blue intensity\n0 0 0 255 0 51 0.5\n1 1 1 0 9 0 1\n".to_vec(),
            ),
            ("semicolon.xyz", b"0.5;1.5;2.5\n-1;-2;-3\n".to_vec()),
        ];
        let obj = vec![
            ("tetra.obj", sepmem::io::obj::encode_mesh(&tetra())),
            ("quad.obj", b"mtllib missing.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nf 1/1/1 2/1/1 3/1/1 4/1/1\n".to_vec()),
            ("points.obj", b"v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n".to_vec()),
            ("groups.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ng a\nf 1 3 2\nf 1 2 4\ng b\nf -4 -1 -2\nf 2 3 4\n".to_vec()),
        ];
        (xyz, obj)
    }

    fn mcap() -> Seeds {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bag.mcap");
        let mut w = sepmem::bag::BagWriter::create(&path).unwrap();
        let m = sepmem::wire::pointcloud2::encode_pointcloud2(&cloud(3), Header::default());
        w.write("/cloud", 1, &m).unwrap();
        w.write("/cloud", 2, &m).unwrap();
        w.write("/other", 3, &m).unwrap();
        w.finish().unwrap();
        let full = std::fs::read(&path).unwrap();
        let cut = full[..full.len() / 2].to_vec();
        vec![
            ("bag.mcap", full),
            ("cut.mcap", cut),
            ("magic.mcap", b"\x89MCAP0\r\n".to_vec()),
        ]
    }

    pub fn all() -> Vec<(&'static str, Seeds)> {
        let (xyz, obj) = text();
        vec![
            ("pointcloud2", pointcloud2()),
            ("ply", ply()),
            ("pcd", pcd()),
            ("xyz", xyz),
            ("obj", obj),
            ("mcap", mcap()),
        ]
    }
}
