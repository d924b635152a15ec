//! GLSL → SPIR-V with shaderc, and the interface check applied to a user's module.
//!
//! Includes resolve, in order, to: `interface.glsl` (generated for the variant from the Rust
//! definitions, see [`crate::interface`]), `layout.glsl` (the variant's layout hooks),
//! `layout/<name>.glsl` (any registered layout's hooks), the shared files of `glsl/`
//! (embedded, so the binary is self-contained), and — for a user's kernel — files beside it.

use super::{Gpu, GpuError};
use crate::interface::{self, binding, PushConstants};
use crate::layout::LayoutId;
use crate::variant::{PacketImpl, Variant};
use std::path::{Path, PathBuf};

/// The shared GLSL sources in `glsl/` (layout hooks come from the registry).
pub const SOURCES: &[(&str, &str)] = &[
    ("ray.glsl", include_str!("../../glsl/ray.glsl")),
    ("tri.glsl", include_str!("../../glsl/tri.glsl")),
    ("box.glsl", include_str!("../../glsl/box.glsl")),
    ("half.glsl", include_str!("../../glsl/half.glsl")),
    ("node16.glsl", include_str!("../../glsl/node16.glsl")),
    ("anchored.glsl", include_str!("../../glsl/anchored.glsl")),
    ("packet.glsl", include_str!("../../glsl/packet.glsl")),
    ("trav.comp", include_str!("../../glsl/trav.comp")),
    ("trav_rq.comp", include_str!("../../glsl/trav_rq.comp")),
    ("bench.comp", include_str!("../../glsl/bench.comp")),
];

/// A shared source by file name.
pub fn source(name: &str) -> Option<&'static str> {
    SOURCES.iter().find(|(n, _)| *n == name).map(|(_, s)| *s)
}

/// What `#include` resolves to for one compilation.
pub struct Includes {
    /// The generated `interface.glsl`.
    pub interface: String,
    /// The variant's layout hooks (`layout.glsl`), if any.
    pub layout: Option<&'static str>,
    /// A user kernel's folder, searched last.
    pub user_dir: Option<PathBuf>,
}

impl Includes {
    /// The includes of a variant's kernel.
    pub fn variant(v: &Variant) -> Includes {
        Includes {
            interface: v.interface_glsl(),
            layout: Some(v.layout.bvh().expect("a BVH layout").glsl()),
            user_dir: None,
        }
    }

    /// The includes of a kernel without a layout (the baselines, the micro-benchmark).
    pub fn plain() -> Includes {
        Includes { interface: interface::glsl_header(None), layout: None, user_dir: None }
    }

    fn resolve(&self, req: &str) -> Result<String, String> {
        if req == "interface.glsl" {
            return Ok(self.interface.clone());
        }
        if req == "layout.glsl" {
            return self.layout.map(str::to_string).ok_or_else(|| "layout.glsl: this kernel has no layout".to_string());
        }
        if let Some(name) = req.strip_prefix("layout/").and_then(|r| r.strip_suffix(".glsl")) {
            if let Some(l) = LayoutId::parse(name).ok().and_then(|l| l.bvh()) {
                return Ok(l.glsl().to_string());
            }
        }
        if let Some(s) = source(req) {
            return Ok(s.to_string());
        }
        if let Some(d) = &self.user_dir {
            let p = d.join(req);
            if let Ok(s) = std::fs::read_to_string(&p) {
                return Ok(s);
            }
        }
        Err(format!("no such include: {req}"))
    }
}

/// Compiles one built-in variant. `f64_fallback`: use fp64 for the watertight test's
/// exact-zero edge case (needs `shaderFloat64`; the CPU reference always does).
pub fn compile(v: &Variant, imp: PacketImpl, stats: bool, f64_fallback: bool) -> Result<Vec<u32>, GpuError> {
    let src = source("trav.comp").expect("glsl/trav.comp is embedded");
    let words = compile_source(
        &v.kernel_name(imp, stats),
        "trav.comp",
        src,
        &v.defines(imp, stats, f64_fallback),
        &Includes::variant(v),
    )?;
    Ok(add_float_modes(&words, &super::support::float_modes(v)))
}

/// Adds float-control execution modes `(mode, width)` (and their capabilities) to the entry
/// point of a compiled module. glslang keeps one `spirv_execution_mode` per mode, whatever the
/// width, so the host adds them; modes already present are kept once.
pub fn add_float_modes(words: &[u32], modes: &[super::support::FloatMode]) -> Vec<u32> {
    if modes.is_empty() || words.len() < 5 {
        return words.to_vec();
    }
    // (start, op, operands) of each instruction.
    let mut insts = Vec::new();
    let mut i = 5;
    while i < words.len() {
        let wc = ((words[i] >> 16) as usize).max(1);
        insts.push((i, words[i] & 0xffff, &words[(i + 1).min(words.len())..(i + wc).min(words.len())]));
        i += wc;
    }
    let entry = insts.iter().find(|(_, op, o)| *op == 15 && o.len() >= 2).map(|(_, _, o)| o[1]);
    let Some(entry) = entry else { return words.to_vec() };
    let has_cap = |c: u32| insts.iter().any(|(_, op, o)| *op == 17 && o.first() == Some(&c));
    let has_mode = |m: u32, w: u32| insts.iter().any(|(_, op, o)| *op == 16 && o.len() >= 3 && o[1] == m && o[2] == w);
    let mut caps: Vec<u32> = Vec::new();
    for &(m, _) in modes {
        let cap = if m == super::support::ROUNDING_MODE_RTE { 4467 } else { 4466 };
        if !has_cap(cap) && !caps.contains(&cap) {
            caps.push(cap);
        }
    }
    let new_modes: Vec<_> = modes.iter().filter(|&&(m, w)| !has_mode(m, w)).collect();
    let last_cap = insts.iter().rposition(|(_, op, _)| *op == 17);
    let last_mode = insts
        .iter()
        .rposition(|(_, op, _)| *op == 16 || *op == 331)
        .or_else(|| insts.iter().rposition(|(_, op, _)| *op == 15));
    let mut out = words[..5].to_vec();
    for (k, (start, _, o)) in insts.iter().enumerate() {
        out.push(words[*start]);
        out.extend_from_slice(o);
        if Some(k) == last_cap {
            for &c in &caps {
                out.extend([(2 << 16) | 17, c]);
            }
        }
        if Some(k) == last_mode {
            for &&(m, w) in &new_modes {
                out.extend([(4 << 16) | 16, entry, m, w]);
            }
        }
    }
    out
}

/// Compiles a user's GLSL kernel file with the defines and includes of the built-in kernel of
/// `v` (plus the file's own folder).
pub fn compile_user(
    path: &Path,
    v: &Variant,
    imp: PacketImpl,
    stats: bool,
    f64_fallback: bool,
) -> Result<Vec<u32>, GpuError> {
    let src = std::fs::read_to_string(path)
        .map_err(|e| GpuError::Spirv { path: path.display().to_string(), msg: format!("cannot read: {e}") })?;
    let mut inc = Includes::variant(v);
    inc.user_dir = path.parent().map(Path::to_path_buf);
    let file = path.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default();
    let words = compile_source(
        &format!("{} ({})", v.kernel_name(imp, stats), path.display()),
        &file,
        &src,
        &v.defines(imp, stats, f64_fallback),
        &inc,
    )?;
    Ok(add_float_modes(&words, &super::support::float_modes(v)))
}

/// Compiles a shared kernel that has no layout (`trav_rq.comp`, `bench.comp`).
pub fn compile_baseline(name: &str, file: &str) -> Result<Vec<u32>, GpuError> {
    compile_plain(name, file, &[])
}

/// Compiles a shared kernel without a layout, with defines.
pub fn compile_plain(name: &str, file: &str, defines: &[(String, String)]) -> Result<Vec<u32>, GpuError> {
    let src = source(file)
        .ok_or_else(|| GpuError::Compile { variant: name.into(), log: format!("missing source {file}") })?;
    compile_source(name, file, src, defines, &Includes::plain())
}

/// Compiles GLSL compute source with defines; `#include`s resolve through `inc`.
pub fn compile_source(
    name: &str,
    file: &str,
    src: &str,
    defines: &[(String, String)],
    inc: &Includes,
) -> Result<Vec<u32>, GpuError> {
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
        inc.resolve(req).map(|content| shaderc::ResolvedInclude { resolved_name: req.to_string(), content })
    });
    let art = compiler
        .compile_into_spirv(src, shaderc::ShaderKind::Compute, file, "main", Some(&opts))
        .map_err(|e| compile_err(e.to_string()))?;
    Ok(art.as_binary().to_vec())
}

/// A summary of a SPIR-V module's interface.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Interface {
    pub entry_points: Vec<(u32, String)>,
    pub local_size: Option<[u32; 3]>,
    /// (descriptor set, binding) of every decorated variable.
    pub bindings: Vec<(u32, u32)>,
    /// Bytes of the push-constant block, if the module declares one.
    pub push_constant_bytes: Option<u32>,
    /// SpecId of every specialization constant.
    pub spec_ids: Vec<u32>,
    pub capabilities: Vec<u32>,
}

/// Parses the words of a SPIR-V module far enough to read its interface.
pub fn parse_interface(words: &[u32]) -> Result<Interface, String> {
    use std::collections::HashMap;
    if words.len() < 5 {
        return Err("too short to be SPIR-V".into());
    }
    if words[0] != 0x0723_0203 {
        return Err(format!("bad magic number {:#010x} (not SPIR-V, or wrong endianness)", words[0]));
    }
    let mut i = 5;
    let mut itf = Interface::default();
    let (mut sets, mut binds) = (HashMap::new(), HashMap::new());
    // Type sizes for the push-constant block: id → bytes; struct member offsets; constants.
    let mut size: HashMap<u32, u64> = HashMap::new();
    let mut members: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut offsets: HashMap<(u32, u32), u32> = HashMap::new();
    let mut strides: HashMap<u32, u32> = HashMap::new();
    let mut consts: HashMap<u32, u32> = HashMap::new();
    let mut pointee: HashMap<u32, u32> = HashMap::new();
    let mut push_ptr_types = Vec::new();
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
                let name =
                    bytes.split(|&b| b == 0).next().map(|s| String::from_utf8_lossy(s).to_string()).unwrap_or_default();
                itf.entry_points.push((ops[0], name));
            }
            16 if ops.len() >= 5 && ops[1] == 17 => itf.local_size = Some([ops[2], ops[3], ops[4]]),
            71 if ops.len() >= 3 && ops[1] == 34 => {
                sets.insert(ops[0], ops[2]);
            }
            71 if ops.len() >= 3 && ops[1] == 33 => {
                binds.insert(ops[0], ops[2]);
            }
            71 if ops.len() >= 3 && ops[1] == 1 => itf.spec_ids.push(ops[2]),
            71 if ops.len() >= 3 && ops[1] == 6 => {
                strides.insert(ops[0], ops[2]);
            }
            72 if ops.len() >= 4 && ops[2] == 35 => {
                offsets.insert((ops[0], ops[1]), ops[3]);
            }
            21 | 22 if ops.len() >= 2 => {
                size.insert(ops[0], ops[1] as u64 / 8);
            }
            23 if ops.len() >= 3 => {
                let s = size.get(&ops[1]).copied().unwrap_or(0) * ops[2] as u64;
                size.insert(ops[0], s);
            }
            24 if ops.len() >= 3 => {
                let s = size.get(&ops[1]).copied().unwrap_or(0) * ops[2] as u64;
                size.insert(ops[0], s);
            }
            43 if ops.len() >= 3 => {
                consts.insert(ops[1], ops[2]);
            }
            28 if ops.len() >= 3 => {
                let n = consts.get(&ops[2]).copied().unwrap_or(0) as u64;
                let stride =
                    strides.get(&ops[0]).map(|&s| s as u64).unwrap_or_else(|| size.get(&ops[1]).copied().unwrap_or(0));
                size.insert(ops[0], n * stride);
            }
            30 => {
                members.insert(ops[0], ops[1..].to_vec());
            }
            32 if ops.len() >= 3 => {
                pointee.insert(ops[0], ops[2]);
                if ops[1] == 9 {
                    push_ptr_types.push(ops[0]);
                }
            }
            59 if ops.len() >= 3 && ops[2] == 9 => {
                let st = pointee.get(&ops[0]).copied().unwrap_or(0);
                let bytes = members.get(&st).map(|m| {
                    m.iter()
                        .enumerate()
                        .map(|(k, t)| {
                            offsets.get(&(st, k as u32)).copied().unwrap_or(0) as u64
                                + size.get(t).copied().unwrap_or(0)
                        })
                        .max()
                        .unwrap_or(0)
                });
                itf.push_constant_bytes = Some(bytes.unwrap_or(0) as u32);
            }
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

/// Reads a SPIR-V file as words (its interface is checked by [`check_user`], then the module by
/// [`validate_user`]).
pub fn read_spirv(path: &Path) -> Result<Vec<u32>, GpuError> {
    let err = |msg: String| GpuError::Spirv { path: path.display().to_string(), msg };
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
    if bytes.len() % 4 != 0 {
        return Err(err(format!("size {} is not a multiple of 4 bytes", bytes.len())));
    }
    Ok(bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

/// [`validate`] as the error of a user's module at `path`.
pub fn validate_user(path: &Path, words: &[u32]) -> Result<(), GpuError> {
    validate(words).map_err(|m| GpuError::Spirv { path: path.display().to_string(), msg: format!("spirv-val: {m}") })
}

mod spirv_tools {
    //! The SPIRV-Tools validator's C API (libspirv.h), from the static library shaderc links.
    use std::ffi::{c_char, c_void};

    #[repr(C)]
    pub struct Position {
        pub line: usize,
        pub column: usize,
        pub index: usize,
    }

    #[repr(C)]
    pub struct Diagnostic {
        pub position: Position,
        pub error: *mut c_char,
        pub is_text_source: bool,
    }

    /// `SPV_ENV_VULKAN_1_2` and `SPV_ENV_VULKAN_1_3` of `spv_target_env`.
    pub const ENV_VULKAN_1_2: u32 = 23;
    pub const ENV_VULKAN_1_3: u32 = 25;

    extern "C" {
        pub fn spvContextCreate(env: u32) -> *mut c_void;
        pub fn spvContextDestroy(ctx: *mut c_void);
        pub fn spvValidateBinary(
            ctx: *const c_void,
            words: *const u32,
            num_words: usize,
            diagnostic: *mut *mut Diagnostic,
        ) -> i32;
        pub fn spvDiagnosticDestroy(d: *mut Diagnostic);
    }
}

/// Validates a module for Vulkan 1.2 (SPIR-V up to 1.5) or 1.3 (SPIR-V 1.6); the validator's
/// message on failure.
pub fn validate(words: &[u32]) -> Result<(), String> {
    use spirv_tools::*;
    let env = if words.get(1).is_some_and(|&v| v >= 0x0001_0600) { ENV_VULKAN_1_3 } else { ENV_VULKAN_1_2 };
    // SAFETY: the context and diagnostic are created and destroyed here, exactly once each; the
    // validator reads `words` only within its length; the message is copied before the
    // diagnostic is destroyed.
    unsafe {
        let ctx = spvContextCreate(env);
        if ctx.is_null() {
            return Err("SPIRV-Tools could not create a validation context".into());
        }
        let mut diag: *mut Diagnostic = std::ptr::null_mut();
        let r = spvValidateBinary(ctx, words.as_ptr(), words.len(), &mut diag);
        let msg = if diag.is_null() || (*diag).error.is_null() {
            None
        } else {
            let m = std::ffi::CStr::from_ptr((*diag).error).to_string_lossy().trim().to_string();
            let word = (*diag).position.index;
            Some(if word > 0 { format!("{m} (at word {word})") } else { m })
        };
        if !diag.is_null() {
            spvDiagnosticDestroy(diag);
        }
        spvContextDestroy(ctx);
        match (r, msg) {
            (0, _) => Ok(()),
            (_, Some(m)) => Err(m),
            (code, None) => Err(format!("invalid module (SPIRV-Tools result {code})")),
        }
    }
}

/// SPIR-V capabilities a traversal kernel may declare, and whether `gpu` (as halftrace opens
/// it) provides each.
fn capability(gpu: &Gpu, cap: u32) -> Option<(&'static str, bool)> {
    let i = &gpu.info;
    let sub = |bit: u32| i.subgroup_ops & (1 << bit) != 0;
    Some(match cap {
        1 => ("Shader", true),
        9 => ("Float16", i.shader_float16),
        10 => ("Float64", i.shader_float64),
        4433 => ("StorageBuffer16BitAccess", i.storage_16bit),
        4466 => ("SignedZeroInfNanPreserve", i.preserve_16 || i.preserve_32),
        4467 => ("RoundingModeRTE", i.fp16_rte || i.fp32_rte),
        61 => ("GroupNonUniform", sub(0)),
        62 => ("GroupNonUniformVote", sub(1)),
        63 => ("GroupNonUniformArithmetic", sub(2)),
        64 => ("GroupNonUniformBallot", sub(3)),
        65 => ("GroupNonUniformShuffle", sub(4)),
        66 => ("GroupNonUniformShuffleRelative", sub(5)),
        67 => ("GroupNonUniformClustered", sub(6)),
        68 => ("GroupNonUniformQuad", sub(7)),
        5347 => ("PhysicalStorageBufferAddresses", i.buffer_device_address),
        _ => return None,
    })
}

/// Checks that a user's module can stand in for the kernel of variant `v` (implementation
/// `imp`, counting or not) on `gpu`; returns the module, or an error that names the file and
/// what differs.
pub fn check_user(
    path: &Path,
    words: &[u32],
    v: &Variant,
    imp: PacketImpl,
    stats: bool,
    gpu: &Gpu,
) -> Result<Vec<u32>, GpuError> {
    let name = v.kernel_name(imp, stats);
    let err = |msg: String| GpuError::Spirv {
        path: path.display().to_string(),
        msg: format!("cannot stand in for {name}: {msg}"),
    };
    let itf = parse_interface(words).map_err(|m| GpuError::Spirv { path: path.display().to_string(), msg: m })?;
    if !itf.entry_points.iter().any(|(model, n)| *model == 5 && n == "main") {
        return Err(err(format!("no GLCompute entry point named 'main' (found {:?})", itf.entry_points)));
    }
    let wg = v.workgroup(imp);
    match itf.local_size {
        Some([x, 1, 1]) if x == wg => {}
        other => return Err(err(format!("its workgroup size is {other:?}; the variant dispatches ({wg}, 1, 1)"))),
    }
    for &(set, b) in &itf.bindings {
        if set != 0 || b >= binding::COUNT {
            return Err(err(format!(
                "it uses set {set}, binding {b}; the traversal interface is set 0, bindings 0..={}",
                binding::COUNT - 1
            )));
        }
    }
    for (need, what) in [(binding::RAYS, "rays"), (binding::HITS, "hits")] {
        if !itf.bindings.contains(&(0, need)) {
            return Err(err(format!("it does not use binding {need} ({what}), so it cannot be a traversal kernel")));
        }
    }
    if v.buffers == crate::variant::Buffers::Bound && itf.capabilities.contains(&5347) {
        return Err(err("it reads buffers by address (PhysicalStorageBufferAddresses: built with ADDRESSED?), but this scene's buffers are bound, and binding 0 holds the nodes, not addresses".into()));
    }
    if v.buffers == crate::variant::Buffers::Addressed {
        if let Some(b) = [binding::TRI_VERTS, binding::TRI_IDS].into_iter().find(|&b| itf.bindings.contains(&(0, b))) {
            return Err(err(format!(
                "it reads binding {b}, but this scene's buffers exceed the device's maxStorageBufferRange ({} bytes) and are read by address (build it from GLSL with ray.glsl's buffers and NODE_BUFFER, which follow the ADDRESSED define)",
                gpu.info.max_storage_buffer
            )));
        }
    }
    let writes_counters = itf.bindings.contains(&(0, binding::COUNTERS));
    if writes_counters && !stats {
        return Err(err(format!(
            "it binds {} (counters): it is a counting kernel, and the timed kernel writes no counters",
            binding::COUNTERS
        )));
    }
    let push = std::mem::size_of::<PushConstants>() as u32;
    match itf.push_constant_bytes {
        None => return Err(err(format!("it declares no push-constant block (the host passes {push} bytes: ray count, node count, root data, root box)"))),
        Some(n) if n > push => return Err(err(format!("its push-constant block is {n} bytes; the host passes {push}"))),
        Some(_) => {}
    }
    if !itf.spec_ids.is_empty() {
        return Err(err(format!("it has specialization constants (SpecId {:?}); the host sets none", itf.spec_ids)));
    }
    // What the module computes must be the variant's: another variant's module of the same
    // layout would return the same hits and be timed under the wrong name.
    let needs = v.layout.bvh().map(|l| l.needs(v.math)).unwrap_or_default();
    let f16 = itf.capabilities.contains(&9);
    if f16 != needs.float16 {
        return Err(err(if f16 {
            format!("it computes in fp16 (Float16 capability), but math {} of {} does not; is it a kernel of another math mode?", v.math.name(), v.layout)
        } else {
            format!("it has no fp16 arithmetic (no Float16 capability), but math {} of {} computes in fp16; is it a kernel of another math mode?", v.math.name(), v.layout)
        }));
    }
    if v.packet == 1 && itf.capabilities.iter().any(|c| (61..=68).contains(c)) {
        return Err(err(
            "it uses subgroup operations: it is a packet kernel, and the variant traces single rays (P = 1)".into(),
        ));
    }
    for &c in &itf.capabilities {
        match capability(gpu, c) {
            Some((_, true)) => {}
            Some((n, false)) => {
                return Err(err(format!("it requires capability {n}, which {} does not provide", gpu.info.name)))
            }
            None => return Err(err(format!("it requires SPIR-V capability {c}, which halftrace does not enable"))),
        }
    }
    Ok(words.to_vec())
}
