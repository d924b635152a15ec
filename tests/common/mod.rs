//! Helpers shared by the integration tests.
#![allow(dead_code)]

use halftrace::base::Hit;
use halftrace::base::Ray;
use halftrace::bvh::{self, BinaryBvh};
use halftrace::layout::{Encoded, LayoutId};
use halftrace::rays::{RayKind, RayParams};
use halftrace::runner::rays::{make, RaySpec};
use halftrace::scene::{self, Scene};
use std::path::PathBuf;

/// The test scenes in the repository: `tests/scenes/*.obj.gz` (sources and licences in
/// `tests/scenes/SOURCES.md`) and the bundled `scenes/teapot.obj`. A fresh clone has them all;
/// nothing here reads `../shared`.
pub fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/scenes")
}

/// The path of test scene `name` (`teapot.obj`, `fandisk.obj`, …): the bundled teapot, or the
/// compressed copy under `tests/scenes`. A missing scene fails the test loudly.
pub fn scene_path(name: &str) -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let p = if name == "teapot.obj" {
        root.join("scenes/teapot.obj")
    } else if name.ends_with(".gz") {
        scenes_dir().join(name)
    } else {
        scenes_dir().join(format!("{name}.gz"))
    };
    assert!(p.is_file(), "test scene {name} not found at {}", p.display());
    p
}

/// Every test scene, sorted by file name.
pub fn all_scenes() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(scenes_dir())
        .unwrap_or_else(|e| panic!("test scenes not found at {}: {e}", scenes_dir().display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".obj.gz"))
        .collect();
    v.push(scene_path("teapot.obj"));
    v.sort_by_key(|p| p.file_name().unwrap().to_owned());
    assert!(v.len() >= 13, "expected the 13 test scenes, found {} files", v.len());
    v
}

pub fn load(name: &str) -> Scene {
    scene::load(&scene_path(name)).unwrap()
}

pub struct Prepared {
    pub scene: Scene,
    pub bin: BinaryBvh,
}

pub fn prepare(path: &std::path::Path) -> Prepared {
    let scene = scene::load(path).unwrap_or_else(|e| panic!("{e}"));
    let bin = bvh::build_binary(&scene);
    Prepared { scene, bin }
}

/// The ray sets the conformance tests use: primary, ao, diffuse at `res`², and grazing rays.
pub fn ray_sets(p: &Prepared, res: u32, grazing: usize) -> Vec<(String, Vec<Ray>)> {
    let params = RayParams { width: res, height: res, camera: None, seed: 7, grazing };
    [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing]
        .into_iter()
        .map(|k| (k.to_string(), make(&p.scene, &p.bin, &RaySpec::new(k, params.clone())).unwrap()))
        .collect()
}

/// Compares two hit lists ray for ray (bitwise); panics naming the variant, the ray and both
/// results at the first mismatches.
pub fn assert_same_hits(what: &str, rays: &[Ray], expected: &[Hit], got: &[Hit]) {
    assert_eq!(expected.len(), got.len(), "{what}: hit count");
    let bad: Vec<usize> = (0..got.len()).filter(|&i| !expected[i].same_bits(&got[i])).collect();
    if !bad.is_empty() {
        let mut msg = format!("{what}: {} of {} rays differ; first ones:\n", bad.len(), got.len());
        for &i in bad.iter().take(5) {
            msg += &format!("  ray {i} {:?}: expected {:?}, got {:?}\n", rays[i], expected[i], got[i]);
        }
        panic!("{msg}");
    }
}

/// The registered layout called `name`.
pub fn layout(name: &str) -> LayoutId {
    LayoutId::parse(name).unwrap()
}

/// Encodes the prepared scene in `layout` at branching `b`.
pub fn encode(p: &Prepared, layout: LayoutId, b: usize) -> Encoded {
    Encoded::new(&p.scene, &p.bin, layout, b).unwrap()
}

/// A baseline (someone else's traversal) against the f32 reference on every test scene:
/// same prim, or t within 1e-5 relative where triangles tie or share edges, on at least
/// 99.99% of primary, ao and diffuse rays. The grazing set (rays through shared vertices and
/// along edges) is reported, not held to the bar: it measures whether the baseline's triangle
/// test is watertight like ours. Each run is timed once after `warmup` untimed ones.
pub fn baseline_agrees_with_f32(name: &str, dev: &dyn halftrace::baseline::BaselineDevice, warmup: usize) {
    baseline_agrees_with_f32_on(name, dev, warmup, &all_scenes());
}

/// [`baseline_agrees_with_f32`] on `scenes`. Where a ray disagrees it says how: a false miss
/// (f32 hits, the baseline misses), a false hit, or another triangle hit at another t.
pub fn baseline_agrees_with_f32_on(
    name: &str,
    dev: &dyn halftrace::baseline::BaselineDevice,
    warmup: usize,
    scenes: &[PathBuf],
) {
    let (mut worst, mut grazing) = (1.0f64, (0usize, 0usize));
    for path in scenes {
        let p = prepare(path);
        let bs = dev.scene(&p.scene).unwrap();
        assert!(bs.bytes() > 0 && bs.build_ms() > 0.0, "{name}: no size or build time");
        let f = encode(&p, LayoutId::f32(), 4);
        for (kind, rays) in ray_sets(&p, 48, 1500) {
            let out = bs.run(&rays, warmup, 1).unwrap();
            assert_eq!(
                (out.hits.len(), out.times_ms.len()),
                (rays.len(), 1),
                "{name}: one hit per ray, one time per timed run"
            );
            let want = f.reference_default(&rays).0;
            let a = halftrace::base::agreement(&out.hits, &want);
            let false_hits = out.hits.iter().zip(&want).filter(|(g, w)| g.is_hit() && !w.is_hit()).count();
            eprintln!(
                "{} {kind}: {name} agrees with f32 on {:.4}% of {} rays ({} false misses, {false_hits} false hits, {} \
                 other triangles)",
                p.scene.name,
                100.0 * a.rate(),
                a.total,
                a.false_misses,
                a.total - a.agree - a.false_misses - false_hits
            );
            if kind == "grazing" {
                grazing.0 += a.agree;
                grazing.1 += a.total;
            } else {
                worst = worst.min(a.rate());
                assert!(
                    a.rate() >= 0.9999,
                    "{} {kind}: {name} agreement {:.4}% < 99.99%",
                    p.scene.name,
                    100.0 * a.rate()
                );
            }
        }
    }
    eprintln!(
        "{name} vs f32: worst primary/ao/diffuse agreement {:.4}%, grazing set {:.3}% ({} of {})",
        100.0 * worst,
        100.0 * grazing.0 as f64 / grazing.1 as f64,
        grazing.0,
        grazing.1
    );
}
