//! What a user's module must be to stand in for a built-in kernel ([`check_user`]: entry
//! point, workgroup, bindings, push constants, capabilities the device has), and the
//! SPIRV-Tools validator ([`validate`]), whose message beats a driver's "unknown error".

use super::spirv::parse_interface;
use crate::gpu::{Gpu, GpuError};
use crate::interface::{binding, PushConstants};
use crate::variant::{Buffers, KernelId};
use rspirv::spirv::{Capability, ExecutionModel};
use std::path::Path;

/// [`validate`] as the error of a user's module at `path`.
pub fn validate_user(path: &Path, words: &[u32]) -> Result<(), GpuError> {
    validate(words).map_err(|m| GpuError::Spirv { path: path.display().to_string(), msg: format!("spirv-val: {m}") })
}

mod spirv_tools {
    //! The SPIRV-Tools validator's C API (libspirv.h), from the static library shaderc links.
    //! Not the `spirv-tools` crate: it compiles SPIRV-Tools' C++ itself (about 200 files: 17.7
    //! minutes of a cold build here, 11.5 CPU-minutes) or runs the `spirv-val` binary, and
    //! cannot link the library already linked for shaderc.
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

/// The subgroup capabilities, in the order of Vulkan's `VkSubgroupFeatureFlagBits`.
const SUBGROUP_OPS: [Capability; 8] = [
    Capability::GroupNonUniform,
    Capability::GroupNonUniformVote,
    Capability::GroupNonUniformArithmetic,
    Capability::GroupNonUniformBallot,
    Capability::GroupNonUniformShuffle,
    Capability::GroupNonUniformShuffleRelative,
    Capability::GroupNonUniformClustered,
    Capability::GroupNonUniformQuad,
];

/// Whether `gpu` (as halftrace opens it) provides a SPIR-V capability a traversal kernel may
/// declare; `None` for any other capability.
fn capability(gpu: &Gpu, cap: Capability) -> Option<bool> {
    let i = &gpu.info;
    if let Some(bit) = SUBGROUP_OPS.iter().position(|&c| c == cap) {
        return Some(i.subgroup_ops & (1 << bit) != 0);
    }
    Some(match cap {
        Capability::Shader => true,
        Capability::Float16 => i.shader_float16,
        Capability::Float64 => i.shader_float64,
        Capability::StorageBuffer16BitAccess => i.storage_16bit,
        Capability::SignedZeroInfNanPreserve => i.preserve_16 || i.preserve_32,
        Capability::RoundingModeRTE => i.fp16_rte || i.fp32_rte,
        Capability::PhysicalStorageBufferAddresses => i.buffer_device_address,
        _ => return None,
    })
}

/// Checks that a user's module can stand in for built-in kernel `k` (its variant, packet
/// implementation, counting or not) on `gpu`; returns the module, or an error that names the
/// file and what differs.
pub fn check_user(path: &Path, words: &[u32], k: &KernelId, gpu: &Gpu) -> Result<Vec<u32>, GpuError> {
    let (v, imp, stats) = (&k.variant, k.imp, k.stats);
    let name = k.name();
    let err = |msg: String| GpuError::Spirv {
        path: path.display().to_string(),
        msg: format!("cannot stand in for {name}: {msg}"),
    };
    let itf = parse_interface(words).map_err(|m| GpuError::Spirv { path: path.display().to_string(), msg: m })?;
    if !itf.entry_points.iter().any(|(model, n)| *model == ExecutionModel::GLCompute && n == "main") {
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
    if v.buffers == Buffers::Bound && itf.capabilities.contains(&Capability::PhysicalStorageBufferAddresses) {
        return Err(err("it reads buffers by address (PhysicalStorageBufferAddresses: built with ADDRESSED?), but this scene's buffers are bound, and binding 0 holds the nodes, not addresses".into()));
    }
    if v.buffers == Buffers::Addressed {
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
    let needs = (v.layout.info().needs)(v.math);
    let f16 = itf.capabilities.contains(&Capability::Float16);
    if f16 != needs.float16 {
        return Err(err(if f16 {
            format!("it computes in fp16 (Float16 capability), but math {} of {} does not; is it a kernel of another math mode?", v.math.name(), v.layout)
        } else {
            format!("it has no fp16 arithmetic (no Float16 capability), but math {} of {} computes in fp16; is it a kernel of another math mode?", v.math.name(), v.layout)
        }));
    }
    if v.packet == 1 && itf.capabilities.iter().any(|c| SUBGROUP_OPS.contains(c)) {
        return Err(err(
            "it uses subgroup operations: it is a packet kernel, and the variant traces single rays (P = 1)".into(),
        ));
    }
    for &c in &itf.capabilities {
        match capability(gpu, c) {
            Some(true) => {}
            Some(false) => {
                return Err(err(format!("it requires capability {c:?}, which {} does not provide", gpu.info.name)))
            }
            None => return Err(err(format!("it requires SPIR-V capability {c:?}, which halftrace does not enable"))),
        }
    }
    Ok(words.to_vec())
}
