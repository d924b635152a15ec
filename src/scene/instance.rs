//! Big test scenes without shipping them: a glTF binary that instances a scene.

use super::Scene;
use crate::base::Rng;
use glam::Vec3;

/// A glTF binary (`.glb`) that instances `scene` `count` times — the big-scene generator: one
/// mesh (the scene's triangles, unindexed), `count` nodes on a grid spaced 1.5 × the scene's
/// largest extent, each rotated about a random axis and scaled uniformly in [0.5, 2] (from
/// `seed`; the first instance untransformed). Returns the file's bytes.
pub fn instanced_glb(scene: &Scene, count: usize, seed: u64) -> Vec<u8> {
    let mut bin: Vec<u8> = Vec::with_capacity(scene.tris.len() * 36);
    for t in &scene.tris {
        for v in t {
            for c in [v.x, v.y, v.z] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    let (lo, hi) = (scene.bounds.min, scene.bounds.max);
    let ext = (hi - lo).max_element().max(f32::MIN_POSITIVE);
    let side = (count as f64).cbrt().ceil() as usize;
    let mut rng = Rng::new(seed);
    let mut nodes = Vec::with_capacity(count);
    for i in 0..count {
        let cell = Vec3::new((i % side) as f32, ((i / side) % side) as f32, (i / (side * side)) as f32);
        let t = cell * (1.5 * ext) - lo;
        if i == 0 {
            nodes.push(format!(r#"{{"mesh":0,"translation":[{},{},{}]}}"#, t.x, t.y, t.z));
            continue;
        }
        let axis = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5)
            .try_normalize()
            .unwrap_or(Vec3::Y);
        let q = glam::Quat::from_axis_angle(axis, rng.next_f32() * std::f32::consts::TAU);
        let s = 0.5 * 4f32.powf(rng.next_f32());
        nodes.push(format!(
            r#"{{"mesh":0,"translation":[{},{},{}],"rotation":[{},{},{},{}],"scale":[{s},{s},{s}]}}"#,
            t.x, t.y, t.z, q.x, q.y, q.z, q.w
        ));
    }
    let n = scene.tris.len() * 3;
    let json = format!(
        r#"{{"asset":{{"version":"2.0","generator":"halftrace instance"}},"scene":0,"scenes":[{{"nodes":[{}]}}],"nodes":[{}],"meshes":[{{"name":"{}","primitives":[{{"attributes":{{"POSITION":0}}}}]}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}],"bufferViews":[{{"buffer":0,"byteLength":{}}}],"buffers":[{{"byteLength":{}}}]}}"#,
        (0..count).map(|i| i.to_string()).collect::<Vec<_>>().join(","),
        nodes.join(","),
        scene.name.replace(['"', '\\'], "_"),
        lo.x,
        lo.y,
        lo.z,
        hi.x,
        hi.y,
        hi.z,
        bin.len(),
        bin.len()
    );
    let mut j = json.into_bytes();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + j.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}
