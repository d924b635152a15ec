//! GLSL → SPIR-V with shaderc (sources embedded in the binary, `#include`s resolved among
//! them), and the interface check applied to user-supplied SPIR-V modules.

use super::GpuError;
use crate::variant::{PacketImpl, Variant};

/// The GLSL sources in `glsl/`, embedded so the binary is self-contained.
pub const SOURCES: &[(&str, &str)] = &[
    ("ray.glsl", include_str!("../../glsl/ray.glsl")),
    ("tri.glsl", include_str!("../../glsl/tri.glsl")),
    ("box.glsl", include_str!("../../glsl/box.glsl")),
    ("frame.glsl", include_str!("../../glsl/frame.glsl")),
    ("node.glsl", include_str!("../../glsl/node.glsl")),
    ("trav_f32.comp", include_str!("../../glsl/trav_f32.comp")),
    ("trav_f16h.comp", include_str!("../../glsl/trav_f16h.comp")),
    ("packet.glsl", include_str!("../../glsl/packet.glsl")),
    ("trav_f32_packet.comp", include_str!("../../glsl/trav_f32_packet.comp")),
    ("trav_f16h_packet.comp", include_str!("../../glsl/trav_f16h_packet.comp")),
    ("trav_rq.comp", include_str!("../../glsl/trav_rq.comp")),
    ("bench.comp", include_str!("../../glsl/bench.comp")),
];

fn source(name: &str) -> Option<&'static str> {
    SOURCES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// Compiles one variant. `f64_fallback`: use fp64 for the watertight test's exact-zero edge
/// case (needs `shaderFloat64`; the CPU reference always does).
pub fn compile(v: &Variant, imp: PacketImpl, stats: bool, f64_fallback: bool) -> Result<Vec<u32>, GpuError> {
    let file = v.source_file();
    let name = v.kernel_name(imp, stats);
    let src = source(file).ok_or_else(|| GpuError::Compile { variant: name.clone(), log: format!("missing source {file}") })?;
    compile_source(&name, file, src, &v.defines(imp, stats, f64_fallback))
}

/// Compiles GLSL compute source (which may `#include` the files in `glsl/`) with defines.
pub fn compile_source(name: &str, file: &str, src: &str, defines: &[(String, String)]) -> Result<Vec<u32>, GpuError> {
    let compile_err = |log: String| GpuError::Compile { variant: name.to_string(), log };
    let compiler = shaderc::Compiler::new().map_err(|e| compile_err(format!("shaderc unavailable: {e}")))?;
    let mut opts = shaderc::CompileOptions::new().map_err(|e| compile_err(format!("shaderc options: {e}")))?;
    opts.set_target_env(shaderc::TargetEnv::Vulkan, shaderc::EnvVersion::Vulkan1_2 as u32);
    opts.set_target_spirv(shaderc::SpirvVersion::V1_5);
    opts.set_optimization_level(shaderc::OptimizationLevel::Performance);
    for (k, val) in defines {
        opts.add_macro_definition(k, Some(val));
    }
    opts.set_include_callback(|req, _ty, _from, _depth| {
        source(req)
            .map(|s| shaderc::ResolvedInclude { resolved_name: req.to_string(), content: s.to_string() })
            .ok_or_else(|| format!("no such include: {req}"))
    });
    let art = compiler.compile_into_spirv(src, shaderc::ShaderKind::Compute, file, "main", Some(&opts)).map_err(|e| compile_err(e.to_string()))?;
    Ok(art.as_binary().to_vec())
}

/// What a traversal module must look like to be dispatched in place of a built-in one.
pub const EXPECTED_BINDINGS: [u32; 6] = [0, 1, 2, 3, 4, 5];

/// A summary of a SPIR-V module's interface.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Interface {
    pub entry_points: Vec<(u32, String)>,
    pub local_size: Option<[u32; 3]>,
    /// (descriptor set, binding) of every decorated variable.
    pub bindings: Vec<(u32, u32)>,
    pub push_constants: bool,
    pub capabilities: Vec<u32>,
}

/// Parses the words of a SPIR-V module far enough to read its interface.
pub fn parse_interface(words: &[u32]) -> Result<Interface, String> {
    if words.len() < 5 {
        return Err("too short to be SPIR-V".into());
    }
    if words[0] != 0x0723_0203 {
        return Err(format!("bad magic number {:#010x} (not SPIR-V, or wrong endianness)", words[0]));
    }
    let mut i = 5;
    let mut itf = Interface::default();
    let mut sets = std::collections::HashMap::new();
    let mut binds = std::collections::HashMap::new();
    let mut last_op = 0;
    while i < words.len() {
        let wc = (words[i] >> 16) as usize;
        let op = words[i] & 0xffff;
        if wc == 0 || i + wc > words.len() {
            return Err(format!("truncated or malformed: the instruction at word {i} runs past the end"));
        }
        let ops = &words[i + 1..i + wc];
        match op {
            17 if !ops.is_empty() => itf.capabilities.push(ops[0]),
            15 if ops.len() >= 3 => {
                let bytes: Vec<u8> = ops[2..].iter().flat_map(|w| w.to_le_bytes()).collect();
                let name = bytes.split(|&b| b == 0).next().map(|s| String::from_utf8_lossy(s).to_string()).unwrap_or_default();
                itf.entry_points.push((ops[0], name));
            }
            16 if ops.len() >= 5 && ops[1] == 17 => itf.local_size = Some([ops[2], ops[3], ops[4]]),
            71 if ops.len() >= 3 && ops[1] == 34 => {
                sets.insert(ops[0], ops[2]);
            }
            71 if ops.len() >= 3 && ops[1] == 33 => {
                binds.insert(ops[0], ops[2]);
            }
            59 if ops.len() >= 3 && ops[2] == 9 => itf.push_constants = true,
            _ => {}
        }
        last_op = op;
        i += wc;
    }
    if last_op != 56 {
        return Err("truncated or malformed: the module does not end with OpFunctionEnd".into());
    }
    let mut b: Vec<(u32, u32)> = binds.iter().map(|(id, b)| (*sets.get(id).unwrap_or(&0), *b)).collect();
    b.sort();
    itf.bindings = b;
    Ok(itf)
}

/// Loads a user SPIR-V file and checks it can stand in for a traversal kernel whose
/// workgroup has `local_size` invocations.
pub fn load_checked(path: &std::path::Path, local_size: u32) -> Result<Vec<u32>, GpuError> {
    let err = |msg: String| GpuError::Spirv { path: path.display().to_string(), msg };
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
    if bytes.len() % 4 != 0 {
        return Err(err(format!("size {} is not a multiple of 4 bytes", bytes.len())));
    }
    let words: Vec<u32> = bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    let itf = parse_interface(&words).map_err(err)?;
    if !itf.entry_points.iter().any(|(model, name)| *model == 5 && name == "main") {
        return Err(err(format!("no GLCompute entry point named 'main' (found {:?})", itf.entry_points)));
    }
    match itf.local_size {
        Some([x, 1, 1]) if x == local_size => {}
        other => return Err(err(format!("workgroup size must be ({local_size}, 1, 1), found {other:?}"))),
    }
    for &(set, b) in &itf.bindings {
        if set != 0 || !EXPECTED_BINDINGS.contains(&b) {
            return Err(err(format!("unexpected binding (set {set}, binding {b}); the traversal interface is set 0, bindings 0..=5")));
        }
    }
    for need in [3, 4] {
        if !itf.bindings.contains(&(0, need)) {
            return Err(err(format!("binding {need} ({}) is not used; the module cannot be a traversal kernel", if need == 3 { "rays" } else { "hits" })));
        }
    }
    if !itf.push_constants {
        return Err(err("no push-constant block (ray count and root frame are passed that way)".into()));
    }
    Ok(words)
}
