//! What a device lacks: missing features fall back to what stays exact, scenes beyond one storage buffer are read by address or refused by name, huge coordinates keep every hit.

use super::*;

/// A device without a feature runs what does not need it, with the same hits, and skips the
/// rest with a line naming the feature: shaderFloat64 → everything (the triangle test's fp64
/// fallback emulated); shaderFloat16 → f32, rq and f16h with fp32 math;
/// 16-bit storage → everything (fp16 nodes are read from 32-bit words); float controls →
/// every conservative layout through its build without them (f16h-poster skipped);
/// clustered subgroup operations (SwiftShader has none) → hybrid packets, and without subgroup
/// arithmetic → shared-memory packets, the subgroup kernels refused by name.
#[test]
fn missing_features_fall_back_to_what_stays_exact() {
    use halftrace::gpu::support;
    use halftrace::precision::{FcChoice, FloatControls};
    let p = prepare(&scene_path("teapot.obj"));
    let rays = &ray_sets(&p, 24, 200)[3].1;
    let f16h = layout("f16h");
    let cases: [(&str, Vec<Variant>, Vec<Variant>); 7] = [
        (
            // The triangle test's fp64 edge recomputation, emulated with integers.
            "shaderFloat64",
            vec![Variant::new(LayoutId::f32(), 4, 1), Variant::new(layout("q8"), 8, 1).with_math(Math::F16)],
            vec![],
        ),
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
            vec![
                Variant::new(LayoutId::f32(), 4, 1),
                Variant::new(f16h, 4, 1).with_math(Math::F32),
                Variant::new(f16h, 8, 8).with_math(Math::F16),
                Variant::new(layout("f16w"), 4, 1).with_math(Math::F32),
                Variant::new(layout("f16a"), 8, 1).with_math(Math::F32),
                Variant::new(layout("q8"), 4, 1).with_math(Math::F32),
            ],
            vec![],
        ),
        (
            "floatControls",
            vec![
                Variant::new(LayoutId::f32(), 4, 1),
                Variant::new(LayoutId::f32(), 4, 4),
                Variant::new(f16h, 4, 1).with_math(Math::F16),
                Variant::new(f16h, 8, 8).with_math(Math::F32),
                Variant::new(layout("f16w"), 4, 1).with_math(Math::F16),
                Variant::new(layout("f16a"), 8, 1).with_math(Math::F32),
                Variant::new(layout("q8"), 4, 4).with_math(Math::F16),
            ],
            vec![Variant::new(layout("f16h-poster"), 4, 1)],
        ),
        (
            "subgroupSizeControl",
            vec![Variant::new(LayoutId::f32(), 4, 4), Variant::new(f16h, 4, 8).with_math(Math::F16)],
            vec![],
        ),
        (
            "subgroupClustered",
            vec![Variant::new(LayoutId::f32(), 4, 4), Variant::new(f16h, 4, 8).with_math(Math::F16)],
            vec![],
        ),
        ("subgroupArithmetic", vec![Variant::new(LayoutId::f32(), 4, 4)], vec![]),
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
            let imp = support::packet_plan(&g.info, v.packet).0;
            let want = match feature {
                "subgroupClustered" => PacketImpl::Hybrid,
                "subgroupArithmetic" => PacketImpl::Shared,
                _ => imp,
            };
            assert_eq!(imp, want, "{feature} masked: {v}");
            if imp != PacketImpl::Subgroup && v.packet > 1 {
                let e = support::admit(&g.info, &KernelId::new(v, PacketImpl::Subgroup, false))
                    .expect_err("a subgroup kernel without clustered operations is refused");
                assert!(e.to_string().contains("clustered subgroup operations"), "{e}");
            }
            let k = builtin(&g, &v, imp, true);
            assert_eq!(
                k.subgroup.is_some(),
                imp == PacketImpl::Subgroup && feature != "subgroupSizeControl",
                "{v}: subgroup size pinned only with subgroupSizeControl"
            );
            let out = k.run(&g, &gb, rays, 0, 1).unwrap();
            let (want, counters) = enc.trace_raw(rays, v.packet, v.math, v.fc);
            assert_same_hits(&format!("{feature} masked: {}", k.name()), rays, &want, &out.hits);
            let mut resolved = out.hits.clone();
            enc.resolve(rays, &mut resolved);
            assert_same_hits(
                &format!("{feature} masked: {} vs f32", k.name()),
                rays,
                &encode(&p, LayoutId::f32(), 4).reference_default(rays).0,
                &resolved,
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
            let e = support::admit(&g.info, &KernelId::new(v, PacketImpl::Single, false))
                .expect_err("an unsupported kernel is not admitted");
            assert!(e.contains(&named), "{e}");
        }
        clean(&g);
    }
    // The rq baseline without ray queries is one skipped line (sweep).
    let g = Gpu::new(&ContextOptions { mask_features: vec!["rayQuery".into()], ..Default::default() }).unwrap();
    assert!(halftrace::baseline::BaselineId::parse("rq").unwrap().imp().unavailable(&g.info).is_some());
    // Through the CLI: shaderFloat16 masked, f16h with fp32 math is validated and traced.
    let out = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .args([
            "trace",
            "--scene",
            scene_path("teapot.obj").to_str().unwrap(),
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
            scene_path("teapot.obj").to_str().unwrap(),
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
    let p = prepare(&scene_path("teapot.obj"));
    let sets = ray_sets(&p, 16, 100);
    for layout in LayoutId::all() {
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
        for &math in layout.info().maths {
            for (pk, imp) in [(1, PacketImpl::Single), (8, PacketImpl::Subgroup)] {
                let v = Variant::new(layout, 8, pk).with_math(math).with_buffers(Buffers::Addressed);
                let k = builtin(&g, &v, imp, true);
                for (kind, rays) in &sets {
                    let what = format!("{} {kind}", v.kernel_name(imp, true));
                    let (hits, counters) = enc.trace_raw(rays, pk, math, v.fc);
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
    let p = prepare(&scene_path("teapot.obj"));
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

/// `trace` on a scene beyond one storage buffer (a pretended 16 KiB limit, through
/// HALFTRACE_MAX_STORAGE_BUFFER): the built-in kernel and a user's GLSL kernel read it by
/// address and are validated; a SPIR-V module that binds the triangles is refused, by name.
#[test]
fn trace_reads_a_scene_beyond_one_storage_buffer_by_address() {
    let sc = scene_path("teapot.obj");
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

/// The kernels keep every hit of a scene with coordinates near 1e20 (their triangle test
/// scales huge coordinates like the CPU reference; a mismatch fails the trace).
#[test]
fn huge_coordinates_trace_on_the_gpu() {
    let src = std::fs::read_to_string(scene_path("teapot.obj")).unwrap();
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
