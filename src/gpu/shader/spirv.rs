//! Reading and patching SPIR-V: one instruction walker ([`instructions`]) under the
//! interface summary of a user's module ([`parse_interface`]), the float-control modes the
//! host adds to a compiled kernel ([`add_float_modes`]) and the tests' checks of `spirv/`.

use super::super::support::{FloatMode, ROUNDING_MODE_RTE};
use crate::gpu::GpuError;
use std::collections::HashMap;
use std::path::Path;

/// The SPIR-V magic number, in the module's endianness.
pub const MAGIC: u32 = 0x0723_0203;

/// Opcodes and operands this module reads (SPIR-V 1.5 specification, section 3).
pub mod op {
    pub const ENTRY_POINT: u32 = 15;
    pub const EXECUTION_MODE: u32 = 16;
    pub const CAPABILITY: u32 = 17;
    pub const TYPE_INT: u32 = 21;
    pub const TYPE_FLOAT: u32 = 22;
    pub const TYPE_VECTOR: u32 = 23;
    pub const TYPE_MATRIX: u32 = 24;
    pub const TYPE_ARRAY: u32 = 28;
    pub const TYPE_STRUCT: u32 = 30;
    pub const TYPE_POINTER: u32 = 32;
    pub const CONSTANT: u32 = 43;
    pub const FUNCTION_END: u32 = 56;
    pub const VARIABLE: u32 = 59;
    pub const DECORATE: u32 = 71;
    pub const MEMBER_DECORATE: u32 = 72;
    pub const EXECUTION_MODE_ID: u32 = 331;
    /// Execution mode LocalSize.
    pub const LOCAL_SIZE: u32 = 17;
    /// Decorations.
    pub const SPEC_ID: u32 = 1;
    pub const ARRAY_STRIDE: u32 = 6;
    pub const BINDING: u32 = 33;
    pub const DESCRIPTOR_SET: u32 = 34;
    pub const OFFSET: u32 = 35;
    /// Storage class PushConstant.
    pub const PUSH_CONSTANT: u32 = 9;
    /// Execution model GLCompute.
    pub const GL_COMPUTE: u32 = 5;
    /// Capabilities.
    pub const FLOAT16: u32 = 9;
    pub const SIGNED_ZERO_INF_NAN_PRESERVE: u32 = 4466;
    pub const ROUNDING_MODE_RTE: u32 = 4467;
    pub const PHYSICAL_STORAGE_BUFFER_ADDRESSES: u32 = 5347;
}

/// One instruction: the word it starts at, its opcode and its operands.
#[derive(Clone, Copy, Debug)]
pub struct Inst<'a> {
    pub start: usize,
    pub op: u32,
    pub operands: &'a [u32],
}

/// The instructions of a module after its five-word header; an error says why the module
/// does not decode (too short, wrong magic, an instruction that runs past the end).
pub fn instructions(words: &[u32]) -> Result<Vec<Inst<'_>>, String> {
    if words.len() < 5 {
        return Err("too short to be SPIR-V".into());
    }
    if words[0] != MAGIC {
        return Err(format!("bad magic number {:#010x} (not SPIR-V, or wrong endianness)", words[0]));
    }
    let mut out = Vec::new();
    let mut i = 5;
    while i < words.len() {
        let wc = (words[i] >> 16) as usize;
        if wc == 0 || i + wc > words.len() {
            return Err(format!("truncated or malformed: the instruction at word {i} runs past the end"));
        }
        out.push(Inst { start: i, op: words[i] & 0xffff, operands: &words[i + 1..i + wc] });
        i += wc;
    }
    Ok(out)
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
    let insts = instructions(words)?;
    let mut itf = Interface::default();
    let (mut sets, mut binds) = (HashMap::new(), HashMap::new());
    // Type sizes for the push-constant block: id → bytes; struct member offsets; constants.
    let mut size: HashMap<u32, u64> = HashMap::new();
    let mut members: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut offsets: HashMap<(u32, u32), u32> = HashMap::new();
    let mut strides: HashMap<u32, u32> = HashMap::new();
    let mut consts: HashMap<u32, u32> = HashMap::new();
    let mut pointee: HashMap<u32, u32> = HashMap::new();
    let size_of = |size: &HashMap<u32, u64>, id: u32| size.get(&id).copied().unwrap_or(0);
    for Inst { op, operands: o, .. } in &insts {
        match *op {
            op::CAPABILITY if !o.is_empty() => itf.capabilities.push(o[0]),
            op::ENTRY_POINT if o.len() >= 3 => {
                let bytes: Vec<u8> = o[2..].iter().flat_map(|w| w.to_le_bytes()).collect();
                let name =
                    bytes.split(|&b| b == 0).next().map(|s| String::from_utf8_lossy(s).to_string()).unwrap_or_default();
                itf.entry_points.push((o[0], name));
            }
            op::EXECUTION_MODE if o.len() >= 5 && o[1] == op::LOCAL_SIZE => itf.local_size = Some([o[2], o[3], o[4]]),
            op::DECORATE if o.len() >= 3 => match o[1] {
                op::DESCRIPTOR_SET => {
                    sets.insert(o[0], o[2]);
                }
                op::BINDING => {
                    binds.insert(o[0], o[2]);
                }
                op::SPEC_ID => itf.spec_ids.push(o[2]),
                op::ARRAY_STRIDE => {
                    strides.insert(o[0], o[2]);
                }
                _ => {}
            },
            op::MEMBER_DECORATE if o.len() >= 4 && o[2] == op::OFFSET => {
                offsets.insert((o[0], o[1]), o[3]);
            }
            op::TYPE_INT | op::TYPE_FLOAT if o.len() >= 2 => {
                size.insert(o[0], o[1] as u64 / 8);
            }
            op::TYPE_VECTOR | op::TYPE_MATRIX if o.len() >= 3 => {
                let s = size_of(&size, o[1]) * o[2] as u64;
                size.insert(o[0], s);
            }
            op::CONSTANT if o.len() >= 3 => {
                consts.insert(o[1], o[2]);
            }
            op::TYPE_ARRAY if o.len() >= 3 => {
                let n = consts.get(&o[2]).copied().unwrap_or(0) as u64;
                let stride = strides.get(&o[0]).map(|&s| s as u64).unwrap_or_else(|| size_of(&size, o[1]));
                size.insert(o[0], n * stride);
            }
            op::TYPE_STRUCT if !o.is_empty() => {
                members.insert(o[0], o[1..].to_vec());
            }
            op::TYPE_POINTER if o.len() >= 3 => {
                pointee.insert(o[0], o[2]);
            }
            op::VARIABLE if o.len() >= 3 && o[2] == op::PUSH_CONSTANT => {
                let st = pointee.get(&o[0]).copied().unwrap_or(0);
                let end = |(k, t): (usize, &u32)| {
                    offsets.get(&(st, k as u32)).copied().unwrap_or(0) as u64 + size_of(&size, *t)
                };
                let bytes = members.get(&st).map(|m| m.iter().enumerate().map(end).max().unwrap_or(0));
                itf.push_constant_bytes = Some(bytes.unwrap_or(0) as u32);
            }
            _ => {}
        }
    }
    if insts.last().map(|i| i.op) != Some(op::FUNCTION_END) {
        return Err("truncated or malformed: the module does not end with OpFunctionEnd".into());
    }
    let mut b: Vec<(u32, u32)> = binds.iter().map(|(id, b)| (*sets.get(id).unwrap_or(&0), *b)).collect();
    b.sort();
    itf.bindings = b;
    Ok(itf)
}

/// Adds float-control execution modes `(mode, width)` (and their capabilities) to the entry
/// point of a compiled module. glslang keeps one `spirv_execution_mode` per mode, whatever the
/// width, so the host adds them; modes already present are kept once. A module that does not
/// decode is returned unchanged (the validator then names what is wrong with it).
pub fn add_float_modes(words: &[u32], modes: &[FloatMode]) -> Vec<u32> {
    let Ok(insts) = instructions(words) else { return words.to_vec() };
    if modes.is_empty() {
        return words.to_vec();
    }
    let entry = insts.iter().find(|i| i.op == op::ENTRY_POINT && i.operands.len() >= 2).map(|i| i.operands[1]);
    let Some(entry) = entry else { return words.to_vec() };
    let has_cap = |c: u32| insts.iter().any(|i| i.op == op::CAPABILITY && i.operands.first() == Some(&c));
    let has_mode = |m: u32, w: u32| {
        insts
            .iter()
            .any(|i| i.op == op::EXECUTION_MODE && i.operands.len() >= 3 && i.operands[1] == m && i.operands[2] == w)
    };
    let mut caps: Vec<u32> = Vec::new();
    for &(m, _) in modes {
        let cap = if m == ROUNDING_MODE_RTE { op::ROUNDING_MODE_RTE } else { op::SIGNED_ZERO_INF_NAN_PRESERVE };
        if !has_cap(cap) && !caps.contains(&cap) {
            caps.push(cap);
        }
    }
    let new_modes: Vec<_> = modes.iter().filter(|&&(m, w)| !has_mode(m, w)).collect();
    let last_cap = insts.iter().rposition(|i| i.op == op::CAPABILITY);
    let last_mode = insts
        .iter()
        .rposition(|i| i.op == op::EXECUTION_MODE || i.op == op::EXECUTION_MODE_ID)
        .or_else(|| insts.iter().rposition(|i| i.op == op::ENTRY_POINT));
    let mut out = words[..5].to_vec();
    for (k, i) in insts.iter().enumerate() {
        out.extend_from_slice(&words[i.start..i.start + 1 + i.operands.len()]);
        if Some(k) == last_cap {
            for &c in &caps {
                out.extend([(2 << 16) | op::CAPABILITY, c]);
            }
        }
        if Some(k) == last_mode {
            for &&(m, w) in &new_modes {
                out.extend([(4 << 16) | op::EXECUTION_MODE, entry, m, w]);
            }
        }
    }
    out
}

/// Reads a SPIR-V file as words (its interface is checked by `check::check_user`, then the
/// module by `check::validate_user`).
pub fn read_spirv(path: &Path) -> Result<Vec<u32>, GpuError> {
    let err = |msg: String| GpuError::Spirv { path: path.display().to_string(), msg };
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
    if bytes.len() % 4 != 0 {
        return Err(err(format!("size {} is not a multiple of 4 bytes", bytes.len())));
    }
    Ok(bytes.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}
