//! The Vulkan backend on the default device (lavapipe in CI), with the Khronos validation
//! layer on: every variant of every registered layout equals the CPU reference of its layout
//! ray for ray (hits bitwise, counters exactly), the shader reads every node layout as Rust
//! writes it, user kernels are checked, validated and timed, no validation message, no leaked
//! allocation, and bad input gets a clear error.

mod common;
use common::*;
use halftrace::bvh::BRANCHINGS;
use halftrace::gpu::buffer::Buffer;
use halftrace::gpu::kernel::{GpuBvh, Kernel, Source};
use halftrace::gpu::pipeline::ComputePipeline;
use halftrace::gpu::shader::{self, Includes};
use halftrace::gpu::{ContextOptions, Gpu, GpuError};
use halftrace::interface::{binding, PushConstants};
use halftrace::layout::{LayoutId, Math};
use halftrace::rays::Ray;
use halftrace::variant::{PacketImpl, Variant, PACKETS};
use std::path::PathBuf;
use std::process::Command;

/// Opens the default device with validation. A machine without Vulkan fails here, loudly:
/// CI always has lavapipe (scripts/install-deps.sh).
fn gpu() -> Gpu {
    let g = Gpu::new(&ContextOptions { validation: true, ..Default::default() }).unwrap_or_else(|e| {
        panic!("GPU TESTS CANNOT RUN: no usable Vulkan device ({e}). Run scripts/install-deps.sh (Mesa lavapipe).")
    });
    assert!(
        g.validation_enabled,
        "VK_LAYER_KHRONOS_validation is not installed (package vulkan-validationlayers); GPU tests require it"
    );
    g
}

fn clean(g: &Gpu) {
    let msgs = g.validation_messages();
    assert!(msgs.is_empty(), "validation messages:\n{}", msgs.join("\n"));
    assert_eq!(g.allocated_bytes(), 0, "allocations leaked");
}

fn builtin<'g>(g: &'g Gpu, v: &Variant, imp: PacketImpl, stats: bool) -> Kernel<'g> {
    Kernel::build(g, v, imp, stats, &Source::Builtin).unwrap_or_else(|e| panic!("{}: {e}", v.kernel_name(imp, stats)))
}

/// `halftrace conformance --quick` over every shared scene under the validation layer: every
/// layout, B, P, math mode, float-control mode and packet implementation runs at least once
/// and equals the CPU reference of its layout (hits bitwise, counters exactly) and the f32
/// hits. The full cross product is `halftrace conformance` (CI runs it after the tests).
#[test]
fn quick_conformance_covers_every_value_on_every_scene() {
    use halftrace::conformance::{self, Status};
    use halftrace::variant::FloatControls;
    let mut scenes = all_scenes();
    scenes.insert(0, repo("scenes/teapot.obj"));
    let opts = conformance::Options { quick: true, scenes, validation: true, ..Default::default() };
    let o = conformance::run(&opts, |_| {}).unwrap_or_else(|e| panic!("GPU TESTS CANNOT RUN: {e}"));
    let md = conformance::markdown(&o, true);
    assert!(o.validation.is_empty(), "validation messages:\n{}", o.validation.join("\n"));
    let fails = o.failures();
    assert!(
        fails.is_empty(),
        "{}",
        fails
            .iter()
            .map(|c| format!("{}: {}", c.variant.kernel_name(c.imp, false), c.status.label()))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let passed: Vec<_> = o.checks.iter().filter(|c| c.status == Status::Pass).collect();
    assert!(passed.iter().all(|c| c.rays > 1000), "every kernel traced every scene:\n{md}");
    for layout in LayoutId::layouts() {
        let of = |f: &dyn Fn(&&&conformance::Check) -> bool| {
            passed.iter().filter(|c| c.variant.layout == layout).any(|c| f(&c))
        };
        for b in BRANCHINGS {
            assert!(of(&|c| c.variant.branching == b), "{layout}: B={b} not covered\n{md}");
        }
        for p in PACKETS {
            assert!(of(&|c| c.variant.packet == p), "{layout}: P={p} not covered\n{md}");
        }
        for &m in layout.caps().maths {
            assert!(of(&|c| c.variant.math == m), "{layout}: math {} not covered\n{md}", m.name());
        }
        // lavapipe (subgroups of 8, with subgroup arithmetic) runs hybrid packets above P = 8.
        for imp in [PacketImpl::Single, PacketImpl::Shared, PacketImpl::Subgroup, PacketImpl::Hybrid] {
            assert!(of(&|c| c.imp == imp), "{layout}: {imp:?} packets not covered\n{md}");
        }
        if layout.bvh().unwrap().float_controls_off() {
            assert!(
                of(&|c| c.variant.fc == FloatControls::Off && c.variant.packet == 1),
                "{layout}: no kernel without float controls covered\n{md}"
            );
            assert!(
                of(&|c| c.variant.fc == FloatControls::Off && c.imp == PacketImpl::Subgroup),
                "{layout}: no packet kernel without float controls covered\n{md}"
            );
        }
    }
    // Both packet implementations at every P the device's subgroup holds.
    let g = gpu();
    for p in PACKETS.into_iter().filter(|&p| p > 1 && p <= g.info.max_subgroup_size as usize) {
        for imp in [PacketImpl::Shared, PacketImpl::Subgroup] {
            assert!(passed.iter().any(|c| c.variant.packet == p && c.imp == imp), "P={p} {imp:?} not covered\n{md}");
        }
    }
    eprintln!("{md}");
}

#[test]
fn odd_ray_counts_and_all_miss_batches() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let sets = ray_sets(&p, 40, 10);
    let rays = &sets[0].1;
    for layout in LayoutId::layouts() {
        let enc = encode(&p, layout, 8);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        let k = builtin(&g, &Variant::new(layout, 8, 1), PacketImpl::Single, false);
        for n in [1usize, 63, 65, 1000] {
            let r = &rays[..n];
            let a = k.run(&g, &gb, r, 1, 2).unwrap();
            assert_eq!(a.times_ms.len(), 2);
            assert_same_hits(&format!("{layout} n={n}"), r, &enc.trace_default(r).0, &a.hits);
        }
        // Rays pointing away from the scene: all misses.
        let away: Vec<Ray> = (0..100)
            .map(|i| Ray { origin: [100.0, i as f32, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY })
            .collect();
        let a = k.run(&g, &gb, &away, 0, 1).unwrap();
        assert!(a.hits.iter().all(|h| h.prim == -1 && h.t == f32::INFINITY));
    }
    clean(&g);
}

/// A kernel that copies every child box and child word back out through each layout's own
/// GLSL hooks proves the layout's GLSL `Node` reads the bytes exactly as its Rust node type
/// writes them (any drift in field order, stride or type shows as a wrong word).
#[test]
fn shader_reads_every_node_layout_as_rust_writes_it() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("fandisk.obj"));
    let src = r#"#version 460
#include "interface.glsl"
#include "ray.glsl"
#include "box.glsl"
#include "layout.glsl"
layout(std430, set = 0, binding = BINDING_COUNTERS) writeonly buffer Out { uint o[]; };
void main() {
    uint i = ray_index();
    if (i >= pc.node_count) return;
    uint b = i * 7u * uint(B);
    for (uint s = 0u; s < uint(B); s++) {
        vec3 lo, hi;
        child_box(i, s, lo, hi);
        for (uint a = 0u; a < 3u; a++) {
            o[b + a * uint(B) + s] = floatBitsToUint(lo[a]);
            o[b + (3u + a) * uint(B) + s] = floatBitsToUint(hi[a]);
        }
        o[b + 6u * uint(B) + s] = child_word(i, s);
    }
}"#;
    for layout in LayoutId::layouts() {
        for b in BRANCHINGS {
            let enc = encode(&p, layout, b);
            let v = Variant::new(layout, b, 1);
            let code = shader::compile_source(
                "node round trip",
                "roundtrip.comp",
                src,
                &v.defines(PacketImpl::Single, false, false),
                &Includes::variant(&v),
            )
            .unwrap();
            let pipe = ComputePipeline::new(
                &g,
                "round trip",
                &code,
                binding::COUNT,
                std::mem::size_of::<PushConstants>() as u32,
            )
            .unwrap();
            let n = enc.node_count();
            let mut expect = vec![0u32; n * 7 * b];
            for node in 0..n {
                for s in 0..b {
                    let (lo, hi) = enc.nodes.child_box(node, s);
                    for a in 0..3 {
                        expect[node * 7 * b + a * b + s] = lo[a].to_bits();
                        expect[node * 7 * b + (3 + a) * b + s] = hi[a].to_bits();
                    }
                    expect[node * 7 * b + 6 * b + s] = enc.nodes.child(node, s);
                }
            }
            let usage = ash::vk::BufferUsageFlags::STORAGE_BUFFER | ash::vk::BufferUsageFlags::TRANSFER_SRC;
            let nodes = Buffer::upload(&g, "nodes", &enc.nodes.to_bytes()).unwrap();
            let out =
                Buffer::new(&g, "out", (n * 7 * b * 4) as u64, usage, gpu_allocator::MemoryLocation::GpuOnly).unwrap();
            let dummy = Buffer::new(&g, "unused", 16, usage, gpu_allocator::MemoryLocation::GpuOnly).unwrap();
            pipe.bind(&[&nodes, &dummy, &dummy, &dummy, &dummy, &out]);
            let push = PushConstants { node_count: n as u32, root: enc.push_root, ..Default::default() };
            g.submit_and_wait(|cmd| {
                pipe.dispatch(cmd, bytemuck::bytes_of(&push), (n as u32).div_ceil(64));
                pipe.barrier(cmd);
            })
            .unwrap();
            let got: Vec<u32> = bytemuck::pod_collect_to_vec(&out.download(n * 7 * b * 4).unwrap());
            assert_eq!(got.len(), expect.len());
            if let Some(i) = (0..got.len()).find(|&i| got[i] != expect[i]) {
                panic!(
                    "{layout} B={b}: word {i} of node {} read as {:#x}, written as {:#x}",
                    i / (7 * b),
                    got[i],
                    expect[i]
                );
            }
        }
    }
    clean(&g);
}

/// A device without a feature runs what does not need it, with the same hits, and skips the
/// rest with a line naming the feature: shaderFloat16 → f32, rq and f16h with fp32 math;
/// 16-bit storage → f32; float controls → every layout through its build without them.
#[test]
fn missing_features_fall_back_to_what_stays_exact() {
    use halftrace::gpu::support;
    use halftrace::variant::{FcChoice, FloatControls};
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let rays = &ray_sets(&p, 24, 200)[3].1;
    let f16h = layout("f16h");
    let cases: [(&str, Vec<Variant>, Vec<Variant>); 4] = [
        (
            "shaderFloat16",
            vec![
                Variant::new(LayoutId::f32(), 4, 1),
                Variant::new(f16h, 4, 1).with_math(Math::F32),
                Variant::new(f16h, 8, 8).with_math(Math::F32),
            ],
            vec![Variant::new(f16h, 4, 1).with_math(Math::F16), Variant::new(f16h, 4, 1).with_math(Math::Mixed)],
        ),
        (
            "storageBuffer16BitAccess",
            vec![Variant::new(LayoutId::f32(), 4, 1)],
            vec![Variant::new(f16h, 4, 1).with_math(Math::F32)],
        ),
        (
            "floatControls",
            vec![
                Variant::new(LayoutId::f32(), 4, 1),
                Variant::new(LayoutId::f32(), 4, 4),
                Variant::new(f16h, 4, 1).with_math(Math::F16),
                Variant::new(f16h, 8, 8).with_math(Math::F32),
            ],
            vec![],
        ),
        (
            "subgroupSizeControl",
            vec![Variant::new(LayoutId::f32(), 4, 4), Variant::new(f16h, 4, 8).with_math(Math::F16)],
            vec![],
        ),
    ];
    for (feature, runs, skips) in cases {
        let g =
            Gpu::new(&ContextOptions { mask_features: vec![feature.into()], validation: true, ..Default::default() })
                .unwrap_or_else(|e| panic!("masking {feature}: the device must still open: {e}"));
        for v in runs {
            let v = support::resolve(&g.info, v, FcChoice::Auto)
                .unwrap_or_else(|e| panic!("{feature} masked: {v} must run: {e}"));
            assert_eq!(
                v.fc == FloatControls::Off,
                feature == "floatControls",
                "{v}: float controls chosen {}",
                v.fc.name()
            );
            let enc = encode(&p, v.layout, v.branching);
            let gb = GpuBvh::upload(&g, &enc).unwrap();
            let imp = halftrace::gpu::kernel::choose_impl(&g, &v, None);
            let k = builtin(&g, &v, imp, true);
            assert_eq!(
                k.subgroup.is_some(),
                imp == PacketImpl::Subgroup && feature != "subgroupSizeControl",
                "{v}: subgroup size pinned only with subgroupSizeControl"
            );
            let out = k.run(&g, &gb, rays, 0, 1).unwrap();
            let (want, counters) = enc.trace_fc(rays, v.packet, v.math, v.fc);
            assert_same_hits(&format!("{feature} masked: {}", k.name()), rays, &want, &out.hits);
            assert_same_hits(
                &format!("{feature} masked: {} vs f32", k.name()),
                rays,
                &encode(&p, LayoutId::f32(), 4).trace_default(rays).0,
                &out.hits,
            );
            assert_eq!(out.counters.unwrap(), counters, "{feature} masked: {} counters", k.name());
        }
        for v in skips {
            let why = support::resolve(&g.info, v, FcChoice::Auto)
                .err()
                .unwrap_or_else(|| panic!("{feature} masked: {v} must be skipped"));
            let named = if feature == "floatControls" {
                "shaderRoundingModeRTEFloat32".to_string()
            } else {
                feature.to_string()
            };
            assert!(why.contains(&named) && why.contains("lacks"), "{why}");
            let e = Kernel::build(&g, &v, PacketImpl::Single, false, &Source::Builtin)
                .err()
                .expect("an unsupported kernel is not built");
            assert!(matches!(e, GpuError::Unsupported(_)), "{e}");
        }
        clean(&g);
    }
    // The rq baseline without ray queries is one skipped line (sweep).
    let g = Gpu::new(&ContextOptions { mask_features: vec!["rayQuery".into()], ..Default::default() }).unwrap();
    assert!(layout("rq").baseline().unwrap().unavailable(&g.info).is_some());
    // Through the CLI: shaderFloat16 masked, f16h with fp32 math is validated and traced.
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "trace",
            "--scene",
            scenes_dir().join("teapot.obj").to_str().unwrap(),
            "--backend",
            "gpu",
            "--layout",
            "f16h",
            "--math",
            "f32",
            "--width",
            "32",
            "--height",
            "32",
            "--mask-feature",
            "shaderFloat16",
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("validated against the CPU reference"),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "trace",
            "--scene",
            scenes_dir().join("teapot.obj").to_str().unwrap(),
            "--backend",
            "gpu",
            "--layout",
            "f16h",
            "--math",
            "f16",
            "--mask-feature",
            "shaderFloat16",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(err.contains("needs shaderFloat16") && err.contains("lacks") && !err.contains("panicked"), "{err}");
}

/// A scene whose buffers exceed `maxStorageBufferRange` (here a pretended 16 KiB limit) is read
/// through buffer device addresses: every layout and math mode, single rays and packets, equals
/// its CPU reference (hits bitwise, counters exactly), under the validation layer.
#[test]
fn scenes_beyond_one_storage_buffer_are_read_by_address() {
    use halftrace::variant::Buffers;
    let g = Gpu::new(&ContextOptions { validation: true, max_buffer: Some(16384), ..Default::default() }).unwrap();
    assert!(g.info.buffer_device_address, "lavapipe has bufferDeviceAddress");
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let sets = ray_sets(&p, 16, 100);
    for layout in LayoutId::layouts() {
        let enc = encode(&p, layout, 8);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        assert_eq!(gb.buffers, Buffers::Addressed, "{layout}: {} bytes do not fit 16 KiB bindings", gb.bytes);
        // A kernel built for bound buffers is refused, not run over the wrong bindings.
        let bound = builtin(&g, &Variant::new(layout, 8, 1), PacketImpl::Single, false);
        let e = bound
            .run(&g, &gb, &sets[0].1, 0, 1)
            .err()
            .expect("a bound kernel on an addressed BVH is refused")
            .to_string();
        assert!(e.contains("Addressed") && e.contains("Bound"), "{e}");
        for &math in layout.caps().maths {
            for (pk, imp) in [(1, PacketImpl::Single), (8, PacketImpl::Subgroup)] {
                let v = Variant::new(layout, 8, pk).with_math(math).with_buffers(Buffers::Addressed);
                let k = builtin(&g, &v, imp, true);
                for (kind, rays) in &sets {
                    let what = format!("{} {kind}", v.kernel_name(imp, true));
                    let (hits, counters) = enc.trace_fc(rays, pk, math, v.fc);
                    let out = k.run(&g, &gb, rays, 0, 1).unwrap_or_else(|e| panic!("{what}: {e}"));
                    assert_same_hits(&what, rays, &hits, &out.hits);
                    assert!(out.counters.as_ref() == Some(&counters), "{what}: counters differ from the CPU reference");
                }
            }
        }
    }
    clean(&g);
}

/// Where the device cannot address buffers, a scene beyond one storage buffer is refused with
/// the limit, the buffer, the variant's layout and B, and the size named.
#[test]
fn scene_too_big_for_the_device_is_a_clear_error() {
    let g = Gpu::new(&ContextOptions {
        max_buffer: Some(4096),
        mask_features: vec!["bufferDeviceAddress".into()],
        ..Default::default()
    })
    .unwrap();
    let p = prepare(&scenes_dir().join("teapot.obj"));
    let enc = encode(&p, layout("f16h"), 4);
    let e = GpuBvh::upload(&g, &enc).err().expect("upload must fail");
    let msg = e.to_string();
    let bytes = enc.node_bytes().to_string();
    assert!(
        msg.contains("nodes (f16h, B=4)")
            && msg.contains(&bytes)
            && msg.contains("maxStorageBufferRange of 4096 bytes")
            && msg.contains("bufferDeviceAddress"),
        "{msg}"
    );
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("halftrace-gpu-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn cli(args: &[&str]) -> (bool, String, String) {
    cli_env(&[], args)
}

/// [`cli`] with environment variables set.
fn cli_env(env: &[(&str, &str)], args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace")).envs(env.iter().copied()).args(args).output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stdout).to_string(), String::from_utf8_lossy(&o.stderr).to_string())
}

/// `trace` on a scene beyond one storage buffer (a pretended 16 KiB limit, through
/// HALFTRACE_MAX_STORAGE_BUFFER): the built-in kernel and a user's GLSL kernel read it by
/// address and are validated; a SPIR-V module that binds the triangles is refused, by name.
#[test]
fn trace_reads_a_scene_beyond_one_storage_buffer_by_address() {
    let sc = scenes_dir().join("teapot.obj");
    let trace = |env: (&str, &str), extra: &[&str]| {
        let mut a = vec![
            "trace",
            "--scene",
            sc.to_str().unwrap(),
            "--layout",
            "f32",
            "--width",
            "16",
            "--height",
            "16",
            "--repeat",
            "1",
        ];
        a.extend_from_slice(extra);
        cli_env(&[env], &a)
    };
    let run = |extra: &[&str]| trace(("HALFTRACE_MAX_STORAGE_BUFFER", "16384"), extra);
    let (ok, out, err) = run(&[]);
    assert!(
        ok && out.contains("read by address")
            && out.contains("trav_f32_b4_p1_addr: validated against the CPU reference"),
        "{out}{err}"
    );
    let user = repo("docs/examples/unordered.comp");
    let (ok, out, err) = run(&["--kernel", user.to_str().unwrap()]);
    assert!(ok && out.contains("read by address") && out.contains("validated against the CPU reference"), "{out}{err}");
    let spv = repo("spirv/trav_f32_b4_p1.spv");
    let (ok, out, err) = run(&["--kernel", spv.to_str().unwrap()]);
    assert!(
        !ok && err.contains("reads binding 1") && err.contains("read by address") && !err.contains("panicked"),
        "{out}{err}"
    );
    // A buffer over maxMemoryAllocationSize (pretended 64 KiB) is refused, naming the limit,
    // the variant, the buffer and its size.
    let (ok, _, err) = trace(("HALFTRACE_MAX_ALLOCATION", "65536"), &[]);
    assert!(
        !ok && err.contains("trav_f32_b4_p1")
            && err.contains("(f32, B=4) needs")
            && err.contains("maxMemoryAllocationSize of 65536 bytes")
            && !err.contains("panicked"),
        "{err}"
    );
}

fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path)
}

#[test]
fn user_kernels_are_checked_then_validated_and_timed() {
    let scene = scenes_dir().join("teapot.obj");
    let sc = scene.to_str().unwrap();
    let small = ["--width", "32", "--height", "32", "--repeat", "2"];
    let run = |args: &[&str]| {
        let mut a = vec!["trace", "--scene", sc];
        a.extend_from_slice(&small);
        a.extend_from_slice(args);
        cli(&a)
    };
    let hits = |name: &str| -> Vec<halftrace::trace::Hit> { halftrace::npy::read_hits(&tmp(name)).unwrap() };
    let out_of = |name: &str| tmp(name).to_str().unwrap().to_string();
    // The built-in kernel's hits, as the reference.
    let (ok, _, err) = run(&["--layout", "f16h", "--branching", "4", "--out", &out_of("builtin.npy")]);
    assert!(ok, "{err}");
    // A module emitted by `shaders --emit` (the copy in spirv/) gives the built-in's hits.
    let spv = repo("spirv/trav_f16h_m16_b4_p1.spv");
    let (ok, out, err) =
        run(&["--layout", "f16h", "--branching", "4", "--kernel", spv.to_str().unwrap(), "--out", &out_of("spv.npy")]);
    assert!(ok, "{err}");
    assert!(
        out.contains("validated against the CPU reference") && out.contains("Mrays/s") && out.contains("user kernel"),
        "{out}"
    );
    assert_eq!(hits("spv.npy"), hits("builtin.npy"));
    // `--spirv` stays an alias.
    let (ok, _, err) = run(&["--layout", "f16h", "--branching", "4", "--spirv", spv.to_str().unwrap()]);
    assert!(ok, "{err}");
    // A GLSL kernel: the documented minimal example, for every layout, gives the built-in's hits.
    let example = repo("docs/examples/unordered.comp");
    for l in LayoutId::layouts() {
        let (ok, out, err) = run(&[
            "--layout",
            l.name(),
            "--branching",
            "8",
            "--kernel",
            example.to_str().unwrap(),
            "--out",
            &out_of("example.npy"),
            "--stats",
        ]);
        assert!(ok, "{l}: {err}");
        assert!(
            out.contains("validated against the CPU reference") && out.contains("writes no counters"),
            "{l}: {out}"
        );
        let (ok, _, err) = run(&["--layout", l.name(), "--branching", "8", "--out", &out_of("example_builtin.npy")]);
        assert!(ok, "{err}");
        assert_eq!(
            hits("example.npy"),
            hits("example_builtin.npy"),
            "{l}: the example kernel's hits differ from the built-in's"
        );
    }
    // A module of another layout fits the interface but returns other hits: validation fails,
    // naming the variant and the user's file, exit non-zero, no hits file.
    let other = repo("spirv/trav_f32_b4_p1.spv");
    let no_hits = tmp("other.npy");
    let _ = std::fs::remove_file(&no_hits);
    // (f16h's fp32 math, like the f32 module, computes without fp16 arithmetic, so only the
    // hits can tell them apart.)
    let (ok, _, err) = run(&[
        "--layout",
        "f16h",
        "--math",
        "f32",
        "--branching",
        "4",
        "--kernel",
        other.to_str().unwrap(),
        "--out",
        no_hits.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("trav_f16h_m32_b4_p1 (user kernel") && err.contains("differ from the CPU reference"),
        "{err}"
    );
    assert!(!no_hits.exists(), "a failed validation wrote a hits file");
    // Interfaces that do not fit the variant are refused before dispatch, naming what differs.
    let counting = repo("spirv/trav_f16h_m16_b4_p1_stats.spv");
    let packet = repo("spirv/trav_f16h_m16_b4_p16.spv");
    for (args, want) in [
        (vec!["--layout", "f16h", "--branching", "4", "--kernel", counting.to_str().unwrap()], "counting kernel"),
        (vec!["--layout", "f16h", "--branching", "4", "--kernel", packet.to_str().unwrap()], "workgroup size"),
    ] {
        let (ok, _, err) = run(&args);
        assert!(!ok && err.contains(want) && err.contains("cannot stand in for trav_f16h_m16_b4_p1"), "{want}: {err}");
    }

    let garbage = tmp("garbage.spv");
    std::fs::write(&garbage, b"definitely not spir-v!!!").unwrap();
    let truncated = tmp("truncated.spv");
    let good = std::fs::read(&spv).unwrap();
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
    // Valid modules with the wrong interface.
    let module = |name: &str, src: &str| {
        let code = shader::compile_source(name, "wrong.comp", src, &[], &Includes::plain()).unwrap();
        let p = tmp(&format!("{name}.spv"));
        std::fs::write(&p, bytemuck::cast_slice(&code)).unwrap();
        p
    };
    let binding9 = module("binding9", "#version 460\nlayout(local_size_x = 64) in;\nlayout(std430, binding = 9) buffer X { float x[]; };\nvoid main() { x[gl_GlobalInvocationID.x] = 1.0; }");
    let big_push = module(
        "bigpush",
        "#version 460\nlayout(local_size_x = 64) in;\nlayout(push_constant) uniform P { vec4 a[5]; } pc;\nlayout(std430, binding = 3) buffer R { float r[]; };\nlayout(std430, binding = 4) buffer H { float h[]; };\nvoid main() { h[gl_GlobalInvocationID.x] = r[0] + pc.a[4].x; }",
    );
    let spec = module(
        "spec",
        "#version 460\nlayout(local_size_x = 64) in;\nlayout(constant_id = 7) const float K = 1.0;\nlayout(push_constant) uniform P { uint n; } pc;\nlayout(std430, binding = 3) buffer R { float r[]; };\nlayout(std430, binding = 4) buffer H { float h[]; };\nvoid main() { h[gl_GlobalInvocationID.x] = r[pc.n] * K; }",
    );
    for (p, what) in [
        (&garbage, "bad magic"),
        (&truncated, "truncated or malformed"),
        (&clean_cut, "does not end with OpFunctionEnd"),
        (&odd, "multiple of 4"),
        (&binding9, "binding 9"),
        (&big_push, "push-constant block is 80 bytes"),
        (&spec, "SpecId [7]"),
    ] {
        let (ok, _, err) = cli(&["trace", "--scene", sc, "--kernel", p.to_str().unwrap()]);
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
    let dir = repo("spirv");
    let mut n = 0;
    let expected = halftrace::variant::spirv_matrix();
    for (v, imp) in &expected {
        for stats in [false, true] {
            let name = v.kernel_name(*imp, stats);
            let p = dir.join(format!("{name}.spv"));
            let on_disk = std::fs::read(&p)
                .unwrap_or_else(|e| panic!("{}: {e}; run `halftrace shaders --emit spirv/`", p.display()));
            let fresh = shader::compile(v, *imp, stats, true).unwrap();
            assert!(
                on_disk == bytemuck::cast_slice::<u32, u8>(&fresh),
                "{} is stale against glsl/; run `halftrace shaders --emit spirv/`",
                p.display()
            );
            let val = Command::new("spirv-val")
                .args(["--target-env", "vulkan1.2"])
                .arg(&p)
                .output()
                .expect("spirv-val (package spirv-tools) is required");
            assert!(val.status.success(), "spirv-val {}: {}", p.display(), String::from_utf8_lossy(&val.stderr));
            // The fp16 math modes must really compute in float16_t; fp32 math and the f32
            // layout must not need fp16 arithmetic (they run on devices without shaderFloat16).
            let ins = instructions(&fresh);
            let f16_cap = ins.iter().any(|(op, o)| *op == 17 && o[0] == 9);
            assert_eq!(f16_cap, v.layout.bvh().unwrap().needs(v.math).float16, "{name}: Float16 capability");
            // Every float-control mode the kernel relies on is declared, per width.
            for (mode, width) in halftrace::gpu::support::float_modes(v) {
                assert!(
                    ins.iter().any(|(op, o)| *op == 16 && o.len() >= 3 && o[1] == mode && o[2] == width),
                    "{name}: execution mode {mode} for fp{width} missing"
                );
            }
            if v.math != Math::F32 {
                let mut f16: Vec<u32> =
                    ins.iter().filter(|(op, o)| *op == 22 && o[1] == 16).map(|(_, o)| o[0]).collect();
                let vecs: Vec<u32> =
                    ins.iter().filter(|(op, o)| *op == 23 && f16.contains(&o[1])).map(|(_, o)| o[0]).collect();
                f16.extend(vecs);
                let count = |opc: u32| ins.iter().filter(|(op, o)| *op == opc && f16.contains(&o[0])).count();
                let (add, sub, mul) = (count(129), count(131), count(133));
                assert!(
                    add > 0 && sub > 0 && mul > 0,
                    "{name}: fp16 OpFAdd {add}, OpFSub {sub}, OpFMul {mul}: box test / origin move not in float16_t"
                );
            }
            n += 1;
        }
    }
    let files = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "spv"))
        .count();
    assert_eq!(files, n, "spirv/ holds files that are not in the default matrix");
    assert_eq!(n, 2 * expected.len());
}

#[test]
fn packet_edge_cases_partial_packets_and_all_misses() {
    let g = gpu();
    let p = prepare(&scenes_dir().join("stanford-bunny.obj"));
    let rays = &ray_sets(&p, 40, 10)[0].1;
    let r1000 = &rays[..1000];
    let away: Vec<Ray> = (0..130)
        .map(|i| Ray { origin: [1.0, i as f32 * 0.01, 0.0], tmin: 0.0, dir: [1.0, 0.0, 0.0], tmax: f32::INFINITY })
        .collect();
    for layout in LayoutId::layouts() {
        let enc = encode(&p, layout, 4);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        let v = Variant::new(layout, 4, 64);
        let k = builtin(&g, &v, PacketImpl::Shared, true);
        let a = k.run(&g, &gb, r1000, 0, 1).unwrap();
        assert_same_hits("1000 rays, P=64", r1000, &enc.trace_default(r1000).0, &a.hits);
        assert_eq!(a.counters.unwrap(), enc.trace(r1000, 64, v.math).1);
        let m = k.run(&g, &gb, &away, 0, 1).unwrap();
        assert!(m.hits.iter().all(|h| h.prim == -1));
        let c = m.counters.unwrap();
        assert!(
            c.iter().all(|c| c.nodes == 0 && c.tri_tests == 0 && c.packet_nodes == 0),
            "all-miss packets visit nothing"
        );
    }
    clean(&g);
}

/// The driver's ray queries (baseline `rq`) against the f32 reference: same prim, or t within
/// 1e-5 relative where triangles tie or share edges; at least 99.99% of primary, ao and
/// diffuse rays on every shared scene. The grazing set (rays through shared vertices and
/// along edges) is reported, not held to the bar: it measures whether the driver's triangle
/// test is watertight, which the Vulkan spec does not require.
#[test]
fn ray_query_baseline_agrees_with_f32_on_every_scene() {
    let g = gpu();
    let rq = layout("rq").baseline().expect("rq is a baseline");
    assert!(
        rq.unavailable(&g.info).is_none(),
        "{} has no ray queries; lavapipe from Mesa >= 24 has them (scripts/install-deps.sh)",
        g.info.name
    );
    let dev = rq.prepare(&g).unwrap();
    baseline_agrees_with_f32("rq", dev.as_ref(), 0);
    drop(dev);
    clean(&g);
}

/// The baseline writes the image, rays and hits it is asked for, like every layout.
#[test]
fn ray_query_baseline_writes_its_outputs() {
    let (img, rays, hits) = (tmp("rq.png"), tmp("rq_rays.npy"), tmp("rq_hits.npy"));
    let scene = scenes_dir().join("teapot.obj");
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        scene.to_str().unwrap(),
        "--layout",
        "rq",
        "--width",
        "24",
        "--height",
        "24",
        "--image",
        img.to_str().unwrap(),
        "--save-rays",
        rays.to_str().unwrap(),
        "--out",
        hits.to_str().unwrap(),
    ]);
    assert!(ok, "{out}{err}");
    assert_eq!(image::open(&img).unwrap().width(), 24);
    assert_eq!(halftrace::npy::read_rays(&rays).unwrap().len(), 576);
    assert_eq!(halftrace::npy::read_hits(&hits).unwrap().len(), 576);
}

/// The kernels keep every hit of a scene with coordinates near 1e20 (their triangle test
/// scales huge coordinates like the CPU reference; a mismatch fails the trace).
#[test]
fn huge_coordinates_trace_on_the_gpu() {
    let src = std::fs::read_to_string(scenes_dir().join("teapot.obj")).unwrap();
    let mut obj = String::new();
    for l in src.lines() {
        if let Some(v) = l.strip_prefix("v ") {
            let c: Vec<f64> = v.split_whitespace().take(3).map(|x| x.parse::<f64>().unwrap() * 1e20).collect();
            obj += &format!("v {} {} {}\n", c[0], c[1], c[2]);
        } else if l.starts_with("f ") {
            obj += l;
            obj.push('\n');
        }
    }
    let p = tmp("teapot_1e20.obj");
    std::fs::write(&p, obj).unwrap();
    for layout in ["f32", "f16h", "q8"] {
        let (ok, out, err) =
            cli(&["trace", "--scene", p.to_str().unwrap(), "--layout", layout, "--width", "32", "--height", "32"]);
        assert!(ok, "{layout}: {out}{err}");
        let hits: usize = out.lines().find_map(|l| l.strip_suffix(" hits")?.parse().ok()).unwrap_or(0);
        assert!(hits > 100, "{layout}: {hits} hits\n{out}");
    }
}

/// A module of another variant of the same layout cannot stand in for the requested one (it
/// would return the same hits and be timed under the wrong name): another math mode or a
/// packet kernel is refused naming the file and why; the user's module is labelled as such.
#[test]
fn user_modules_of_another_variant_are_refused() {
    let scene = scenes_dir().join("teapot.obj");
    let s = scene.to_str().unwrap();
    let spv = |n: &str| repo(&format!("spirv/{n}.spv")).display().to_string();
    for (module, want) in
        [("trav_f16h_m32_b4_p1", "another math mode"), ("trav_f16h_m16_b4_p8_subgroup", "packet kernel")]
    {
        let (ok, out, err) = cli(&[
            "trace",
            "--scene",
            s,
            "--layout",
            "f16h",
            "--math",
            "f16",
            "--kernel",
            &spv(module),
            "--width",
            "8",
            "--height",
            "8",
        ]);
        assert!(!ok && err.contains(module) && err.contains(want), "{module}: {out}{err}");
    }
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        s,
        "--layout",
        "f16h",
        "--math",
        "f16",
        "--kernel",
        &spv("trav_f16h_m16_b4_p1"),
        "--width",
        "8",
        "--height",
        "8",
    ]);
    assert!(ok && out.contains("the user's, in place of trav_f16h_m16_b4_p1"), "{out}{err}");
}

/// An invalid SPIR-V module is refused with the SPIRV-Tools validator's own message, naming
/// the file, before any pipeline is created (not a driver's "unknown error").
#[test]
fn invalid_spirv_gets_the_validators_message() {
    // Well formed (its interface reads fine) but invalid: the Physical32 addressing model,
    // which Vulkan does not allow.
    let good = std::fs::read(repo("spirv/trav_f32_b4_p1.spv")).unwrap();
    let mut words: Vec<u32> = bytemuck::pod_collect_to_vec(&good);
    let i = (5..words.len() - 2).find(|&i| words[i] == (3 << 16 | 14)).expect("OpMemoryModel");
    words[i + 1] = 1;
    let cut = tmp("cut.spv");
    std::fs::write(&cut, bytemuck::cast_slice::<u32, u8>(&words)).unwrap();
    let scene = scenes_dir().join("teapot.obj");
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        scene.to_str().unwrap(),
        "--layout",
        "f32",
        "--kernel",
        cut.to_str().unwrap(),
        "--width",
        "8",
        "--height",
        "8",
    ]);
    assert!(!ok && err.contains("cut.spv") && err.contains("spirv-val"), "{out}{err}");
}

/// A kernel that never terminates is declared hung after --kernel-timeout instead of hanging
/// the process; in a sweep it is recorded as a FAILED row, the sweep stops (the device is still
/// busy with it) and `--resume` continues after it.
#[test]
fn a_kernel_that_never_ends_is_reported_hung() {
    let k = tmp("hang.comp");
    std::fs::write(&k, "#version 460\n#include \"interface.glsl\"\n#include \"ray.glsl\"\nvoid main() {\n    uint i = ray_index();\n    if (i >= pc.ray_count) return;\n    float t = ray_f[8u * i];\n    while (t == t) { t += 1.0; hits[i] = Hit(t, 0, 0.0, 0.0); }\n}\n").unwrap();
    let scene = scenes_dir().join("teapot.obj");
    let t0 = std::time::Instant::now();
    let (ok, out, err) = cli(&[
        "trace",
        "--scene",
        scene.to_str().unwrap(),
        "--layout",
        "f32",
        "--kernel",
        k.to_str().unwrap(),
        "--kernel-timeout",
        "2",
        "--width",
        "8",
        "--height",
        "8",
    ]);
    assert!(!ok && err.contains("within 2 s"), "{out}{err}");
    assert!(t0.elapsed().as_secs() < 60, "took {:?}", t0.elapsed());
    let cfg = tmp("hang.toml");
    std::fs::write(&cfg, format!("scenes = [{:?}]\nrays = [\"primary\"]\nlayouts = [\"f32\"]\nbranchings = [4]\npackets = [1]\nscheme_branchings = [4]\nwidth = 8\nheight = 8\nrepeat = 1\nwarmup = 0\nkernel_timeout = 2.0\n\n[[kernel]]\nname = \"hang\"\nlayout = \"f32\"\nfile = {:?}\n", scene.display().to_string(), k.display().to_string())).unwrap();
    let out_dir = tmp("hang-sweep");
    let _ = std::fs::remove_dir_all(&out_dir);
    let (ok, _, err) =
        cli(&["sweep", "--quiet", "--config", cfg.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(!ok && err.contains("hang") && err.contains("--resume"), "{err}");
    let rows = halftrace::report::read_rows(&out_dir).unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    assert!(
        rows[0].status == "ok" && rows[1].kernel == "hang" && rows[1].status.starts_with("FAILED: hung"),
        "{rows:?}"
    );
    let (ok, _, err) =
        cli(&["sweep", "--quiet", "--config", cfg.to_str().unwrap(), "--out", out_dir.to_str().unwrap(), "--resume"]);
    assert!(ok, "{err}");
    assert_eq!(halftrace::report::read_rows(&out_dir).unwrap().len(), 2);
}

/// `halftrace bench` validates every target, then prints every ratio the speed issue names
/// (median, min, max over its rounds, with the target) and every target's speed; `--out`
/// writes the same report.
#[test]
fn bench_prints_every_ratio_with_medians_and_ranges() {
    let md = tmp("bench.md");
    let scene = repo("scenes/teapot.obj");
    let (ok, out, err) = cli(&[
        "bench",
        "--scene",
        scene.to_str().unwrap(),
        "--width",
        "16",
        "--height",
        "16",
        "--rounds",
        "2",
        "--repeat",
        "1",
        "--out",
        md.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("targets validated"), "{err}");
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(out.contains(&text), "--out differs from what was printed");
    for what in [
        "f16h fp32-math ÷ f32, B = 8, P = 1",
        "f16h fp16-math ÷ f32, B = 8, P = 1",
        "best reduced-precision ÷ f32 (same B), largest scene",
        "best halftrace variant ÷ embree (host CPU)",
        "P = 8 ÷ P = 1, f32, B = 4",
        "P = 64 ÷ P = 1, f32, B = 4",
        "f32 ÷ rq (driver ray queries)",
    ] {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("| {what} |")))
            .unwrap_or_else(|| panic!("no ratio '{what}' in\n{text}"));
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (med, lo, hi): (f64, f64, f64) =
            (cells[5].parse().unwrap(), cells[6].parse().unwrap(), cells[7].parse().unwrap());
        assert!(lo > 0.0 && lo <= med && med <= hi, "{line}");
    }
    for t in ["trav_f32_b8_p1", "trav_f16h_m16_b8_p1", "trav_q8_m32_b4_p1", "rq", "embree"] {
        assert!(text.contains(&format!("| teapot | primary | {t} |")), "no speed of {t}");
    }
    // --layouts narrows the reduced-precision set (f32 stays); a baseline or unknown name is
    // refused before anything runs.
    for (bad, want) in [("rq", "a baseline"), ("f9", "unknown layout 'f9'")] {
        let (ok, _, err) = cli(&["bench", "--scene", scene.to_str().unwrap(), "--layouts", bad]);
        assert!(!ok && err.contains(want), "{bad}: {err}");
    }
}
