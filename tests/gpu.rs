//! The Vulkan backend on the default device (lavapipe in CI), with the Khronos validation
//! layer on: every variant equals the CPU reference of its layout ray for ray (hits
//! bitwise, counters exactly), the shader reads the node layouts as Rust writes them, no
//! validation message, no leaked allocation, and bad input gets a clear error.

mod common;
use common::*;
use halftrace::bvh::BRANCHINGS;
use halftrace::encode::Layout;
use halftrace::gpu::buffer::Buffer;
use halftrace::gpu::pipeline::ComputePipeline;
use halftrace::gpu::{shader, traversal, ContextOptions, Gpu, GpuError};
use halftrace::pipeline::Encoded;
use halftrace::rays::Ray;
use halftrace::variant::{Math, PacketImpl, Variant};
use std::path::PathBuf;
use std::process::Command;

/// Opens the default device with validation. A machine without Vulkan fails here, loudly:
/// CI always has lavapipe (scripts/install-deps.sh).
fn gpu() -> Gpu {
    let g = Gpu::new(&ContextOptions { validation: true, ..Default::default() })
        .unwrap_or_else(|e| panic!("GPU TESTS CANNOT RUN: no usable Vulkan device ({e}). Run scripts/install-deps.sh (Mesa lavapipe)."));
    assert!(g.validation_enabled, "VK_LAYER_KHRONOS_validation is not installed (package vulkan-validationlayers); GPU tests require it");
    g
}

fn clean(g: &Gpu) {
    let msgs = g.validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
    assert_eq!(g.allocated_bytes(), 0, "allocations leaked");
}

#[test]
fn every_variant_equals_the_cpu_reference_on_every_scene() {
    let g = gpu();
    let mut checked = 0usize;
    for path in all_scenes() {
        let p = prepare(&path);
        let sets = ray_sets(&p, 40, 1000);
        for layout in Layout::ALL {
            for b in BRANCHINGS {
              let enc = Encoded::new(&p.scene, &p.bin, layout, b).unwrap();
              let gb = traversal::GpuBvh::upload(&g, &enc).unwrap();
              let maths: &[Math] = if layout == Layout::F16h { &Math::ALL } else { &[Math::F32] };
              for &math in maths {
                let v = Variant::new(layout, b, 1).with_math(math);
                let timed = traversal::pipeline(&g, &v, PacketImpl::Single, false, None).unwrap();
                let stats = traversal::pipeline(&g, &v, PacketImpl::Single, true, None).unwrap();
                for (kind, rays) in &sets {
                    let (hits, counters) = enc.trace_variant(rays, 1, math);
                    let f32_hits = if layout == Layout::F32 { hits.clone() } else { Encoded::new(&p.scene, &p.bin, Layout::F32, b).unwrap().trace(rays).0 };
                    assert_same_hits(&format!("{} {v} {kind}: CPU reference vs f32", p.scene.name), rays, &f32_hits, &hits);
                    let what = format!("{} {v} {kind}", p.scene.name);
                    let a = traversal::run(&g, &gb, &timed, rays, 0, 1).unwrap();
                    assert_same_hits(&format!("{what} (timed kernel) vs CPU"), rays, &hits, &a.hits);
                    let s = traversal::run(&g, &gb, &stats, rays, 0, 1).unwrap();
                    assert_same_hits(&format!("{what} (counting kernel) vs CPU"), rays, &hits, &s.hits);
                    let c = s.counters.unwrap();
                    if let Some(i) = (0..rays.len()).find(|&i| c[i] != counters[i]) {
                        panic!("{what}: ray {i} {:?}: GPU counters {:?}, CPU {:?}", rays[i], c[i], counters[i]);
                    }
                    checked += rays.len();
                }
              }
            }
        }
    }
    eprintln!("{checked} rays checked on {}", g.info.name);
    clean(&g);
}

#[test]
fn odd_ray_counts_and_all_miss_batches() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let sets = ray_sets(&p, 40, 10);
    let rays = &sets[0].1;
    for layout in Layout::ALL {
        let enc = Encoded::new(&p.scene, &p.bin, layout, 8).unwrap();
        let gb = traversal::GpuBvh::upload(&g, &enc).unwrap();
        let pipe = traversal::pipeline(&g, &Variant::new(layout, 8, 1), PacketImpl::Single, false, None).unwrap();
        for n in [1usize, 63, 65, 1000] {
            let r = &rays[..n];
            let a = traversal::run(&g, &gb, &pipe, r, 1, 2).unwrap();
            assert_eq!(a.times_ms.len(), 2);
            assert_same_hits(&format!("{layout} n={n}"), r, &enc.trace(r).0, &a.hits);
        }
        // Rays pointing away from the scene: all misses.
        let away: Vec<Ray> = (0..100).map(|i| Ray { origin: [100.0, i as f32, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY }).collect();
        let a = traversal::run(&g, &gb, &pipe, &away, 0, 1).unwrap();
        assert!(a.hits.iter().all(|h| h.prim == -1 && h.t == f32::INFINITY));
    }
    clean(&g);
}

/// A kernel that copies every node field back out proves the std430 layout in node.glsl
/// matches the Rust structs byte for byte.
#[test]
fn shader_reads_every_node_layout_as_rust_writes_it() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("fandisk.obj"));
    let src = r#"#version 460
#include "ray.glsl"
#include "node.glsl"
layout(std430, set = 0, binding = 5) writeonly buffer Out { uint o[]; };
void main() {
    uint i = ray_index();
    if (i >= pc.node_count) return;
    uint b = i * 7u * uint(B);
    for (uint k = 0u; k < 3u * uint(B); k++) {
        o[b + k] = floatBitsToUint(float(nodes[i].lo[k]));
        o[b + 3u * uint(B) + k] = floatBitsToUint(float(nodes[i].hi[k]));
    }
    for (uint s = 0u; s < uint(B); s++) o[b + 6u * uint(B) + s] = nodes[i].child[s];
}"#;
    for layout in Layout::ALL {
        for b in BRANCHINGS {
            let enc = Encoded::new(&p.scene, &p.bin, layout, b).unwrap();
            let mut defs = vec![("B".to_string(), b.to_string())];
            if layout == Layout::F16h {
                defs.push(("F16H".into(), "1".into()));
            }
            let code = shader::compile_source("node round trip", "roundtrip.comp", src, &defs).unwrap();
            let pipe = ComputePipeline::new(&g, "round trip", &code, traversal::BINDINGS, 64).unwrap();
            let n = enc.node_count();
            let usage = ash::vk::BufferUsageFlags::STORAGE_BUFFER | ash::vk::BufferUsageFlags::TRANSFER_SRC;
            let (bytes, expect): (&[u8], Vec<u32>) = match &enc {
                Encoded::F32(e) => (e.nodes.bytes(), bytemuck::cast_slice::<u8, u32>(e.nodes.bytes()).to_vec()),
                Encoded::F16h(e) => {
                    // Expected: each fp16 coordinate widened to f32 bits, then the child words.
                    let nb = e.nodes.bytes();
                    let per = 16 * b;
                    let mut v = Vec::new();
                    for node in nb.chunks_exact(per) {
                        for c in node[..12 * b].chunks_exact(2) {
                            v.push(half::f16::from_le_bytes([c[0], c[1]]).to_f32().to_bits());
                        }
                        for c in node[12 * b..].chunks_exact(4) {
                            v.push(u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
                        }
                    }
                    (nb, v)
                }
            };
            let nodes = Buffer::upload(&g, "nodes", bytes).unwrap();
            let out = Buffer::new(&g, "out", (n * 7 * b * 4) as u64, usage, gpu_allocator::MemoryLocation::GpuOnly).unwrap();
            let dummy = Buffer::new(&g, "unused", 16, usage, gpu_allocator::MemoryLocation::GpuOnly).unwrap();
            pipe.bind(&[&nodes, &dummy, &dummy, &dummy, &dummy, &out]);
            let mut push = traversal::PushConstants { ray_count: 0, node_count: n as u32, _pad: [0; 2], root_wk: [0.0; 4], box_lo: [0.0; 4], box_hi: [0.0; 4] };
            push.node_count = n as u32;
            g.submit_and_wait(|cmd| {
                pipe.dispatch(cmd, bytemuck::bytes_of(&push), (n as u32).div_ceil(64));
                pipe.barrier(cmd);
            })
            .unwrap();
            let got: Vec<u32> = bytemuck::pod_collect_to_vec(&out.download(n * 7 * b * 4).unwrap());
            assert_eq!(got.len(), expect.len());
            if let Some(i) = (0..got.len()).find(|&i| got[i] != expect[i]) {
                panic!("{layout} B={b}: word {i} of node {} read as {:#x}, written as {:#x}", i / (7 * b), got[i], expect[i]);
            }
        }
    }
    clean(&g);
}

#[test]
fn device_without_fp16_is_a_clear_error() {
    for feature in ["shaderFloat16", "storageBuffer16BitAccess"] {
        let e = Gpu::new(&ContextOptions { mask_features: vec![feature.into()], ..Default::default() }).err().expect("masked device must be refused");
        let msg = e.to_string();
        assert!(matches!(e, GpuError::MissingFeature { .. }), "{msg}");
        assert!(msg.contains(feature) && msg.contains("lacks"), "{msg}");
    }
    // Through the CLI, before anything is dispatched.
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args(["trace", "--scene", scenes_dir().join("teapot.obj").to_str().unwrap(), "--backend", "gpu", "--mask-feature", "shaderFloat16"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("lacks shaderFloat16") && !err.contains("panicked"), "{err}");
}

#[test]
fn scene_too_big_for_the_device_is_a_clear_error() {
    let g = Gpu::new(&ContextOptions { max_buffer: Some(4096), ..Default::default() }).unwrap();
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let enc = Encoded::new(&p.scene, &p.bin, Layout::F16h, 4).unwrap();
    let e = traversal::GpuBvh::upload(&g, &enc).err().expect("upload must fail");
    let msg = e.to_string();
    assert!(msg.contains("nodes (f16h, B=4)") && msg.contains("limit of 4096 bytes"), "{msg}");
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-gpu-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn cli(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace")).args(args).output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stdout).to_string(), String::from_utf8_lossy(&o.stderr).to_string())
}

#[test]
fn raw_spirv_modules_are_checked_then_validated_and_timed() {
    let scene = scenes_dir().join("teapot.obj");
    let sc = scene.to_str().unwrap();
    let repo_spv = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("spirv/trav_f16h_m16_b4_p1.spv");
    // A correct module (the built-in one, from spirv/) runs through validation and timing.
    let (ok, out, err) = cli(&["trace", "--scene", sc, "--layout", "f16h", "--branching", "4", "--width", "32", "--height", "32", "--repeat", "2", "--spirv", repo_spv.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.contains("validated against the CPU reference") && out.contains("Mrays/s"), "{out}");
    // A module for the other layout gives wrong hits: caught by validation, naming the variant.
    let other = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("spirv/trav_f32_b4_p1.spv");
    let (ok, _, err) = cli(&["trace", "--scene", sc, "--layout", "f16h", "--branching", "4", "--width", "32", "--height", "32", "--spirv", other.to_str().unwrap()]);
    assert!(!ok && err.contains("trav_f16h_m16_b4_p1 (custom SPIR-V)") && err.contains("differ from the CPU reference"), "{err}");

    let garbage = tmp("garbage.spv");
    std::fs::write(&garbage, b"definitely not spir-v!!!").unwrap();
    let truncated = tmp("truncated.spv");
    let good = std::fs::read(&repo_spv).unwrap();
    std::fs::write(&truncated, &good[..good.len() / 2 / 4 * 4 + 4]).unwrap();
    // Cut exactly after an instruction in the middle: still not a complete module.
    let words: Vec<u32> = bytemuck::pod_collect_to_vec(&good);
    let (mut i, mut cut) = (5, 5);
    while i < words.len() / 2 {
        cut = i;
        i += (words[i] >> 16) as usize;
    }
    let clean_cut = tmp("clean_cut.spv");
    std::fs::write(&clean_cut, bytemuck::cast_slice::<u32, u8>(&words[..cut])).unwrap();
    let odd = tmp("odd.spv");
    std::fs::write(&odd, &good[..good.len() - 1]).unwrap();
    // A valid module with the wrong interface.
    let wrong = shader::compile_source(
        "wrong",
        "wrong.comp",
        "#version 460\nlayout(local_size_x = 64) in;\nlayout(std430, binding = 9) buffer X { float x[]; };\nvoid main() { x[gl_GlobalInvocationID.x] = 1.0; }",
        &[],
    )
    .unwrap();
    let wrong_p = tmp("wrong.spv");
    std::fs::write(&wrong_p, bytemuck::cast_slice(&wrong)).unwrap();
    for (p, what) in [(&garbage, "bad magic"), (&truncated, "truncated or malformed"), (&clean_cut, "does not end with OpFunctionEnd"), (&odd, "multiple of 4"), (&wrong_p, "binding 9")] {
        let (ok, _, err) = cli(&["trace", "--scene", sc, "--spirv", p.to_str().unwrap()]);
        assert!(!ok, "{what}");
        assert!(err.contains(p.to_str().unwrap()) && err.contains(what) && !err.contains("panicked"), "{what}: {err}");
    }
}

/// Parses SPIR-V words into (opcode, operands).
fn instructions(words: &[u32]) -> Vec<(u32, Vec<u32>)> {
    let mut v = Vec::new();
    let mut i = 5;
    while i < words.len() {
        let wc = (words[i] >> 16) as usize;
        v.push((words[i] & 0xffff, words[i + 1..i + wc].to_vec()));
        i += wc;
    }
    v
}

#[test]
fn spirv_folder_is_fresh_valid_and_really_fp16() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("spirv");
    let mut n = 0;
    let expected = halftrace::variant::spirv_matrix();
    for (v, imp) in &expected {
        for stats in [false, true] {
            let name = v.kernel_name(*imp, stats);
            let p = dir.join(format!("{name}.spv"));
            let on_disk = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}; run `halftrace shaders --emit spirv/`", p.display()));
            let fresh = shader::compile(v, *imp, stats, true).unwrap();
            assert!(on_disk == bytemuck::cast_slice::<u32, u8>(&fresh), "{} is stale against glsl/; run `halftrace shaders --emit spirv/`", p.display());
            let val = Command::new("spirv-val").args(["--target-env", "vulkan1.2"]).arg(&p).output().expect("spirv-val (package spirv-tools) is required");
            assert!(val.status.success(), "spirv-val {}: {}", p.display(), String::from_utf8_lossy(&val.stderr));
            // The fp16 math modes must really compute in float16_t (m32 widens on purpose).
            if v.layout == Layout::F16h && v.math != Math::F32 {
                let ins = instructions(&fresh);
                assert!(ins.iter().any(|(op, o)| *op == 17 && o[0] == 9), "{name}: no Float16 capability");
                let mut f16: Vec<u32> = ins.iter().filter(|(op, o)| *op == 22 && o[1] == 16).map(|(_, o)| o[0]).collect();
                let vecs: Vec<u32> = ins.iter().filter(|(op, o)| *op == 23 && f16.contains(&o[1])).map(|(_, o)| o[0]).collect();
                f16.extend(vecs);
                let count = |opc: u32| ins.iter().filter(|(op, o)| *op == opc && f16.contains(&o[0])).count();
                let (add, sub, mul) = (count(129), count(131), count(133));
                assert!(add > 0 && sub > 0 && mul > 0, "{name}: fp16 OpFAdd {add}, OpFSub {sub}, OpFMul {mul}: box test / origin move not in float16_t");
            }
            n += 1;
        }
    }
    let files = std::fs::read_dir(&dir).unwrap().filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "spv")).count();
    assert_eq!(files, n, "spirv/ holds files that are not in the default matrix");
    assert_eq!(n, 2 * expected.len());
}

/// Packets change the work, never the answer: for every scene, layout, f16h math mode, B, P
/// (both packet implementations where the device allows) and ray kind, GPU hits equal the
/// single-ray f32 hits ray for ray, and GPU counters equal the CPU packet reference of the
/// same mode.
#[test]
fn packet_variants_equal_single_ray_hits_and_packet_reference_counters() {
    use halftrace::trace::packet::PACKETS;
    let g = gpu();
    let mut kernels = Vec::new();
    for layout in Layout::ALL {
        for b in BRANCHINGS {
            for p in PACKETS.into_iter().filter(|&p| p > 1) {
                let maths: &[Math] = if layout == Layout::F16h { &Math::ALL } else { &[Math::F32] };
                for &math in maths {
                    let v = Variant::new(layout, b, p).with_math(math);
                    let mut imps = vec![halftrace::variant::PacketImpl::Shared];
                    // every P on the portable kernel; the subgroup kernel where it fits (seed's math)
                    if p <= g.info.subgroup_size as usize && math != Math::Mixed {
                        imps.push(halftrace::variant::PacketImpl::Subgroup);
                    }
                    for imp in imps {
                        kernels.push((traversal::pipeline(&g, &v, imp, false, None).unwrap(), traversal::pipeline(&g, &v, imp, true, None).unwrap()));
                    }
                }
            }
        }
    }
    let mut checked = 0usize;
    for path in all_scenes() {
        let p = prepare(&path);
        let sets = ray_sets(&p, 12, 120);
        for layout in Layout::ALL {
            for b in BRANCHINGS {
                let enc = Encoded::new(&p.scene, &p.bin, layout, b).unwrap();
                let gb = traversal::GpuBvh::upload(&g, &enc).unwrap();
                // Every packet variant of every math mode must return exactly the f32 hits.
                let f32_enc = Encoded::new(&p.scene, &p.bin, Layout::F32, b).unwrap();
                let single: Vec<_> = sets.iter().map(|(_, rays)| f32_enc.trace(rays).0).collect();
                for (timed, stats) in kernels.iter().filter(|(k, _)| k.variant.layout == layout && k.variant.branching == b) {
                    let pk = timed.variant.packet;
                    for ((kind, rays), want) in sets.iter().zip(&single) {
                        let what = format!("{} {} {kind}", p.scene.name, timed.name());
                        let (cpu_hits, cpu_counters) = enc.trace_variant(rays, pk, timed.variant.math);
                        assert_same_hits(&format!("{what}: CPU packet reference vs single-ray"), rays, want, &cpu_hits);
                        let a = traversal::run(&g, &gb, timed, rays, 0, 1).unwrap();
                        assert_same_hits(&format!("{what} vs single-ray"), rays, want, &a.hits);
                        let s = traversal::run(&g, &gb, stats, rays, 0, 1).unwrap();
                        assert_same_hits(&format!("{what} (counting) vs single-ray"), rays, want, &s.hits);
                        let c = s.counters.unwrap();
                        if let Some(i) = (0..rays.len()).find(|&i| c[i] != cpu_counters[i]) {
                            panic!("{what}: ray {i} (packet {}): GPU counters {:?}, CPU packet reference {:?}", i / pk, c[i], cpu_counters[i]);
                        }
                        checked += rays.len();
                    }
                }
            }
        }
    }
    eprintln!("{checked} packet-traced rays checked");
    drop(kernels);
    clean(&g);
}

#[test]
fn packet_edge_cases_partial_packets_and_all_misses() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("stanford-bunny.obj"));
    let rays = &ray_sets(&p, 40, 10)[0].1;
    let r1000 = &rays[..1000];
    let away: Vec<Ray> = (0..130).map(|i| Ray { origin: [1.0, i as f32 * 0.01, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY }).collect();
    for layout in Layout::ALL {
        let enc = Encoded::new(&p.scene, &p.bin, layout, 4).unwrap();
        let gb = traversal::GpuBvh::upload(&g, &enc).unwrap();
        let v = Variant::new(layout, 4, 64);
        let k = traversal::pipeline(&g, &v, halftrace::variant::PacketImpl::Shared, true, None).unwrap();
        let a = traversal::run(&g, &gb, &k, r1000, 0, 1).unwrap();
        assert_same_hits("1000 rays, P=64", r1000, &enc.trace(r1000).0, &a.hits);
        assert_eq!(a.counters.unwrap(), enc.trace_packets(r1000, 64).1);
        let m = traversal::run(&g, &gb, &k, &away, 0, 1).unwrap();
        assert!(m.hits.iter().all(|h| h.prim == -1));
        let c = m.counters.unwrap();
        assert!(c.iter().all(|c| c.nodes == 0 && c.tri_tests == 0 && c.packet_nodes == 0), "all-miss packets visit nothing");
    }
    clean(&g);
}

/// The driver's ray queries (layout `rq`) against the f32 reference: same prim, or t within
/// 1e-5 relative where triangles tie or share edges; at least 99.99% of primary, ao and
/// diffuse rays on every shared scene. The grazing set (rays through shared vertices and
/// along edges) is reported, not held to the bar: it measures whether the driver's triangle
/// test is watertight, which the Vulkan spec does not require.
#[test]
fn ray_query_layout_agrees_with_f32_on_every_scene() {
    let g = gpu();
    assert!(g.info.ray_query, "{} has no ray queries; lavapipe from Mesa >= 24 has them (scripts/install-deps.sh)", g.info.name);
    let pipe = halftrace::gpu::rq::pipeline(&g).unwrap();
    let (mut worst, mut grazing) = (1.0f64, (0usize, 0usize));
    for path in all_scenes() {
        let p = prepare(&path);
        let rs = halftrace::gpu::rq::RqScene::build(&g, &p.scene).unwrap();
        assert!(rs.bytes > 0 && rs.build_ms > 0.0);
        let f = Encoded::new(&p.scene, &p.bin, Layout::F32, 4).unwrap();
        for (kind, rays) in ray_sets(&p, 48, 1500) {
            let out = halftrace::gpu::rq::run(&g, &rs, &pipe, &rays, 0, 1).unwrap();
            let a = halftrace::trace::agreement(&out.hits, &f.trace(&rays).0);
            eprintln!("{} {kind}: rq agrees with f32 on {:.4}% of {} rays ({} false misses)", p.scene.name, 100.0 * a.rate(), a.total, a.false_misses);
            if kind == "grazing" {
                grazing.0 += a.agree;
                grazing.1 += a.total;
            } else {
                worst = worst.min(a.rate());
                assert!(a.rate() >= 0.9999, "{} {kind}: rq agreement {:.4}% < 99.99%", p.scene.name, 100.0 * a.rate());
            }
        }
    }
    eprintln!("rq vs f32: worst primary/ao/diffuse agreement {:.4}%, grazing set {:.3}% ({} of {})", 100.0 * worst, 100.0 * grazing.0 as f64 / grazing.1 as f64, grazing.0, grazing.1);
    drop(pipe);
    clean(&g);
}
