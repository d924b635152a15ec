//! User kernels: checked against the variant's interface, then validated and timed; modules of another variant and invalid SPIR-V refused by name.

use super::*;
use halftrace::gpu::shader::{self, Includes};
use rspirv::binary::Assemble;
use rspirv::dr::Operand;
use rspirv::spirv::AddressingModel;

#[test]
fn user_kernels_are_checked_then_validated_and_timed() {
    let scene = scene_path("teapot.obj");
    let sc = scene.to_str().unwrap();
    let small = ["--width", "32", "--height", "32", "--repeat", "2"];
    let run = |args: &[&str]| {
        let mut a = vec!["trace", "--scene", sc];
        a.extend_from_slice(&small);
        a.extend_from_slice(args);
        cli(&a)
    };
    let hits = |name: &str| -> Vec<halftrace::base::Hit> { halftrace::npy::read_hits(&tmp(name)).unwrap() };
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
    for l in LayoutId::all() {
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
    let m = shader::spirv::load(&words).unwrap();
    let mut cut = words[..5].to_vec();
    for inst in m.all_inst_iter() {
        if cut.len() >= words.len() / 2 {
            break;
        }
        inst.assemble_into(&mut cut);
    }
    let clean_cut = tmp("clean_cut.spv");
    std::fs::write(&clean_cut, bytemuck::cast_slice::<u32, u8>(&cut)).unwrap();
    let odd = tmp("odd.spv");
    std::fs::write(&odd, &good[..good.len() - 1]).unwrap();
    // Valid modules with the wrong interface.
    let module = |name: &str, src: &str| {
        let code = shader::compile_source(name, "wrong.comp", src, &[], &Includes::plain(), 5).unwrap();
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

/// A module of another variant of the same layout cannot stand in for the requested one (it
/// would return the same hits and be timed under the wrong name): another math mode or a
/// packet kernel is refused naming the file and why; the user's module is labelled as such.
#[test]
fn user_modules_of_another_variant_are_refused() {
    let scene = scene_path("teapot.obj");
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
    let mut m = shader::spirv::load(&bytemuck::pod_collect_to_vec(&good)).unwrap();
    m.memory_model.as_mut().expect("OpMemoryModel").operands[0] = Operand::AddressingModel(AddressingModel::Physical32);
    let words = m.assemble();
    let cut = tmp("cut.spv");
    std::fs::write(&cut, bytemuck::cast_slice::<u32, u8>(&words)).unwrap();
    let scene = scene_path("teapot.obj");
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
