//! The kernels themselves: the GLSL reads every node as Rust writes it, and `spirv/` is fresh, valid and really fp16.

use super::*;
use halftrace::gpu::buffer::Buffer;
use halftrace::gpu::pipeline::ComputePipeline;
use halftrace::gpu::shader::{self, Includes};
use halftrace::interface::{binding, PushConstants};
use rspirv::dr::Operand;
use rspirv::spirv::{Capability, Op};

/// A kernel that copies every child box and child word back out through each layout's own
/// GLSL hooks proves the layout's GLSL `Node` reads the bytes exactly as its Rust node type
/// writes them (any drift in field order, stride or type shows as a wrong word).
#[test]
fn shader_reads_every_node_layout_as_rust_writes_it() {
    let g = gpu();
    let p = prepare(&scene_path("fandisk.obj"));
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
    // Both node reads: fp16 storage, and halves in 32-bit words (devices without 16-bit
    // storage), in every math mode (a conversion or a bit cast per half); the latter as SPIR-V
    // 1.3, what a Vulkan 1.1 device (panvk on Mali) is handed.
    use halftrace::variant::DeviceBuild;
    let words = DeviceBuild { storage16: false, spirv_minor: 3, register_array_bytes: 0, pending_shared: true };
    let builds = LayoutId::all().flat_map(|l| {
        BRANCHINGS.into_iter().flat_map(move |b| {
            l.info().maths.iter().flat_map(move |&m| [(l, b, m, DeviceBuild::FULL), (l, b, m, words)])
        })
    });
    for (layout, b, math, dev) in builds {
        let enc = encode(&p, layout, b);
        let v = Variant::new(layout, b, 1).with_math(math);
        let code = shader::compile_source(
            "node round trip",
            "roundtrip.comp",
            src,
            &v.defines(PacketImpl::Single, false, dev),
            &Includes::variant(&v),
            dev.spirv_minor,
        )
        .unwrap();
        let pipe =
            ComputePipeline::new(&g, "round trip", &code, binding::COUNT, std::mem::size_of::<PushConstants>() as u32)
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
                "{layout} B={b} {math:?} {dev:?}: word {i} of node {} read as {:#x}, written as {:#x}",
                i / (7 * b),
                got[i],
                expect[i]
            );
        }
    }
    clean(&g);
}

#[test]
fn spirv_folder_is_fresh_valid_and_really_fp16() {
    let dir = repo("spirv");
    let mut n = 0;
    let expected = halftrace::variant::spirv_kernels();
    for k in &expected {
        for stats in [false, true] {
            let k = k.with_stats(stats);
            let name = k.name();
            let v = &k.variant;
            let p = dir.join(format!("{name}.spv"));
            let on_disk = std::fs::read(&p)
                .unwrap_or_else(|e| panic!("{}: {e}; run `halftrace shaders --emit spirv/`", p.display()));
            let fresh = shader::compile(&k, halftrace::variant::DeviceBuild::FULL).unwrap();
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
            let m = shader::spirv::load(&fresh).expect("a module that loads");
            let f16_cap = m.capabilities.iter().any(|i| i.operands[0] == Operand::Capability(Capability::Float16));
            assert_eq!(f16_cap, (v.layout.info().needs)(v.math).float16, "{name}: Float16 capability");
            // Every float-control mode the kernel relies on is declared, per width.
            for (mode, width) in halftrace::gpu::support::float_modes(v) {
                let want = [Operand::ExecutionMode(mode), Operand::LiteralBit32(width)];
                assert!(
                    m.execution_modes.iter().any(|i| i.operands[1..] == want),
                    "{name}: execution mode {mode:?} for fp{width} missing"
                );
            }
            if v.math != Math::F32 {
                let types = |op: Op, first: Operand| {
                    m.types_global_values.iter().filter(move |i| i.class.opcode == op && i.operands[0] == first)
                };
                let mut f16: Vec<u32> =
                    types(Op::TypeFloat, Operand::LiteralBit32(16)).filter_map(|i| i.result_id).collect();
                let vecs: Vec<u32> = f16
                    .iter()
                    .flat_map(|&t| types(Op::TypeVector, Operand::IdRef(t)))
                    .filter_map(|i| i.result_id)
                    .collect();
                f16.extend(vecs);
                let count = |op: Op| {
                    m.all_inst_iter()
                        .filter(|i| i.class.opcode == op && i.result_type.is_some_and(|t| f16.contains(&t)))
                        .count()
                };
                let (add, sub, mul) = (count(Op::FAdd), count(Op::FSub), count(Op::FMul));
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

/// `k`'s hits and counters on each ray set equal the CPU reference's for packets of `p` rays
/// (`what` names the build in a failure).
fn assert_matches_reference(
    g: &Gpu,
    k: &Kernel,
    gb: &GpuBvh,
    enc: &halftrace::layout::Encoded,
    sets: &[(String, Vec<Ray>)],
    p: usize,
    what: &str,
) {
    let v = k.id.variant;
    for (kind, rays) in sets {
        let what = format!("{}, {what}, {kind} rays", k.id);
        let a = k.run(g, gb, rays, 0, 1).unwrap();
        let (hits, counters) = enc.trace_raw(rays, p, v.math, v.fc);
        assert_same_hits(&what, rays, &hits, &a.hits);
        assert_eq!(a.counters.unwrap(), counters, "{what}: counters");
    }
}

/// The certified triangle test (glsl/tri.glsl, `tri_certify`) with and without float controls
/// (`FC_OFF`, the build for Mali): grazing rays include rays along triangle edges and
/// axis-parallel rays through vertices, which fp32 cannot decide, so the kernels flag them
/// (`PRIM_FLAGGED`) exactly where the CPU reference does; hits and counters equal the
/// reference's, flags included, and some rays are flagged.
#[test]
fn certified_triangle_test_flags_as_the_reference_does() {
    use halftrace::precision::FloatControls;
    let g = gpu();
    let p = prepare(&scene_path("fandisk.obj"));
    let sets = ray_sets(&p, 32, 4000);
    let mut flagged = 0;
    for layout in [LayoutId::f32(), layout("f16w")] {
        let enc = encode(&p, layout, 4);
        let gb = GpuBvh::upload(&g, &enc).unwrap();
        for fc in [FloatControls::On, FloatControls::Off] {
            let v = Variant::new(layout, 4, 1).with_fc(fc).with_buffers(gb.buffers);
            let k = builtin_as(&g, &v, PacketImpl::Single, true, |_| {});
            assert_matches_reference(&g, &k, &gb, &enc, &sets, 1, "flags");
            for (_, rays) in &sets {
                flagged += enc.trace_raw(rays, 1, v.math, fc).0.iter().filter(|h| h.is_flagged()).count();
            }
        }
    }
    assert!(flagged > 0, "no grazing ray was flagged: the test checks no flag");
    clean(&g);
}

/// The deferred stack's next entry in shared memory (`PENDING_SHARED`, what GPUs other than
/// Intel's build; this CPU device keeps it in registers): f16h and f16h-poster in every math,
/// single rays at every B and B = 4 packets in each implementation (subgroup; shared and
/// hybrid, whose workgroup is the packet), built as for such a GPU, give the CPU reference's
/// hits and counters.
#[test]
fn next_entry_in_shared_memory_equals_the_reference() {
    let g = gpu();
    let p = prepare(&scene_path("fandisk.obj"));
    let sets = ray_sets(&p, 32, 2000);
    let runs = [
        (2, 1, PacketImpl::Single),
        (4, 1, PacketImpl::Single),
        (8, 1, PacketImpl::Single),
        (16, 1, PacketImpl::Single),
        (4, 4, PacketImpl::Subgroup),
        (4, 4, PacketImpl::Shared),
        (4, 16, PacketImpl::Hybrid),
    ];
    for layout in [layout("f16h"), layout("f16h-poster")] {
        for (b, pk, imp) in runs {
            let enc = encode(&p, layout, b);
            let gb = GpuBvh::upload(&g, &enc).unwrap();
            for &math in layout.info().maths {
                let v = Variant::new(layout, b, pk).with_math(math).with_buffers(gb.buffers);
                let k = builtin_as(&g, &v, imp, true, |d| {
                    d.build.pending_shared = true;
                    // The build really is the shared-memory one (lavapipe's own keeps registers).
                    assert!(
                        d.id.variant.defines(d.id.imp, true, d.build).iter().any(|(k, _)| k == "PENDING_SHARED"),
                        "{}: built without PENDING_SHARED",
                        d.id
                    );
                });
                assert_matches_reference(&g, &k, &gb, &enc, &sets, pk, "next entry in shared memory");
            }
        }
    }
    clean(&g);
}

/// The kernel's own count of each named side of its triangle test (the branch-counting build,
/// `Source::Counted`: each `MARK_<NAME>()` increments the ray's count) equals, ray by ray, what
/// the CPU reference's replay counts for `estimate`'s branch weights
/// (`layout::traverse::branch_work` for a wave of one lane): every layout in every math at
/// B = 4, f32 and q8 at B = 8, on the teapot and fandisk, primary, ao, diffuse and grazing rays.
/// Hits and triangle tests are the reference's too, and every side but `huge` and `flat` (which
/// these scenes never take) is taken somewhere, so a wrong count cannot hide.
#[test]
fn kernels_take_the_branches_the_reference_counts() {
    use halftrace::base::tri::Branch;
    use halftrace::layout::traverse::branch_work;
    let g = gpu();
    let mut total = [0u64; 8];
    for scene in ["teapot.obj", "fandisk.obj"] {
        let p = prepare(&scene_path(scene));
        let sets = ray_sets(&p, 24, 500);
        for layout in LayoutId::all() {
            for b in [4, 8] {
                if b == 8 && layout != LayoutId::f32() && layout != self::layout("q8") {
                    continue;
                }
                let enc = encode(&p, layout, b);
                let gb = GpuBvh::upload(&g, &enc).unwrap();
                for &math in layout.info().maths {
                    let v = Variant::new(layout, b, 1).with_math(math).with_buffers(gb.buffers);
                    let k = built_from(&g, &v, PacketImpl::Single, true, &Source::Counted, |_| {});
                    for (kind, rays) in &sets {
                        let what = format!("{}, {scene} {kind} rays", k.label());
                        let a = k.run(&g, &gb, rays, 0, 1).unwrap();
                        let (hits, counters) = enc.trace_raw(rays, 1, v.math, v.fc);
                        assert_same_hits(&what, rays, &hits, &a.hits);
                        let reads = layout.imp().mem_reads(&enc, rays, 1, v.math, v.fc);
                        for (i, gc) in a.counters.unwrap().iter().enumerate() {
                            assert_eq!(gc.tri_tests, counters[i].tri_tests, "{what}: ray {i}'s triangle tests");
                            let cpu = branch_work(&reads[i..=i], &rays[i..=i], &enc.tris, 1, 1).0;
                            let gpu = Branch::counted(gc);
                            for side in Branch::ALL {
                                let (c, k) = (cpu.taken[side as usize], gpu[side as usize] as u64);
                                assert!(k < 0xffff, "{what}: ray {i} {}: the count saturated", side.name());
                                assert_eq!(
                                    k,
                                    if side.marker().is_some() { c } else { 0 },
                                    "{what}: ray {i} took `{}` {k} times in the kernel, {c} in the reference's replay",
                                    side.name()
                                );
                                total[side as usize] += k;
                            }
                        }
                    }
                }
            }
        }
    }
    for side in [Branch::Edges, Branch::Cross, Branch::Divide, Branch::Candidate, Branch::Best] {
        assert!(total[side as usize] > 0, "no ray took `{}`: {total:?}", side.name());
    }
    eprintln!("sides taken, summed over the runs: {total:?}");
    clean(&g);
}
