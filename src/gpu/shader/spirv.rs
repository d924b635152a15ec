//! Reading and patching SPIR-V with rspirv: one loader ([`load`]) under the interface summary
//! of a user's module ([`parse_interface`]), the float-control modes the host adds to a
//! compiled kernel ([`add_float_modes`]) and the tests' checks of `spirv/`.

use super::super::support::FloatMode;
use crate::gpu::GpuError;
use rspirv::binary::{Assemble, ParseState};
use rspirv::dr::{self, Instruction, Module, Operand};
use rspirv::spirv::{Capability, Decoration, ExecutionMode, ExecutionModel, Op, StorageClass, Word};
use std::collections::HashMap;
use std::path::Path;

/// Loads a module; an error says why it does not decode (too short, wrong magic, an
/// instruction that runs past the end or breaks the grammar, a function cut short).
///
/// rspirv's loader keeps the header's version and bound but not its generator and reserved
/// words; they are put back, so `load(w)?.assemble() == w` for every module halftrace builds.
pub fn load(words: &[u32]) -> Result<Module, String> {
    let mut m = dr::load_words(words).map_err(|e| match e {
        ParseState::HeaderIncomplete(_) => "too short to be SPIR-V".to_string(),
        ParseState::HeaderIncorrect | ParseState::EndiannessUnsupported => {
            format!("bad magic number {:#010x} (not SPIR-V, or wrong endianness)", words[0])
        }
        ParseState::ConsumerError(e) => match e.downcast_ref::<dr::Error>() {
            Some(dr::Error::UnclosedBlock | dr::Error::UnclosedFunction) => unended(),
            _ => format!("truncated or malformed: {e}"),
        },
        e => format!("truncated or malformed: {e}"),
    })?;
    if m.functions.is_empty() {
        return Err(unended());
    }
    if let Some(h) = m.header.as_mut() {
        (h.generator, h.reserved_word) = (words[2], words[4]);
    }
    Ok(m)
}

fn unended() -> String {
    "truncated or malformed: the module does not end with OpFunctionEnd".into()
}

/// A summary of a SPIR-V module's interface.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Interface {
    pub entry_points: Vec<(ExecutionModel, String)>,
    pub local_size: Option<[u32; 3]>,
    /// (descriptor set, binding) of every decorated variable.
    pub bindings: Vec<(u32, u32)>,
    /// Bytes of the push-constant block, if the module declares one.
    pub push_constant_bytes: Option<u32>,
    /// SpecId of every specialization constant.
    pub spec_ids: Vec<u32>,
    pub capabilities: Vec<Capability>,
}

/// The id or literal word of an operand.
fn word(o: &Operand) -> Option<Word> {
    match *o {
        Operand::IdRef(w) | Operand::LiteralBit32(w) => Some(w),
        _ => None,
    }
}

/// Parses a SPIR-V module far enough to read its interface.
pub fn parse_interface(words: &[u32]) -> Result<Interface, String> {
    let m = load(words)?;
    let mut itf = Interface::default();
    let (mut sets, mut binds) = (HashMap::new(), HashMap::new());
    // Type sizes for the push-constant block: id → bytes; struct member offsets; constants.
    let mut size: HashMap<Word, u64> = HashMap::new();
    let mut members: HashMap<Word, Vec<Word>> = HashMap::new();
    let mut offsets: HashMap<(Word, u32), u32> = HashMap::new();
    let mut strides: HashMap<Word, u32> = HashMap::new();
    let mut consts: HashMap<Word, u32> = HashMap::new();
    let mut pointee: HashMap<Word, Word> = HashMap::new();
    let size_of = |size: &HashMap<Word, u64>, id: Word| size.get(&id).copied().unwrap_or(0);
    for i in m.all_inst_iter() {
        let (o, id) = (i.operands.as_slice(), i.result_id.unwrap_or(0));
        let w = |k: usize| o.get(k).and_then(word);
        match (i.class.opcode, o) {
            (Op::Capability, [Operand::Capability(c)]) => itf.capabilities.push(*c),
            (Op::EntryPoint, [Operand::ExecutionModel(model), _, Operand::LiteralString(name), ..]) => {
                itf.entry_points.push((*model, name.clone()))
            }
            (Op::ExecutionMode, [_, Operand::ExecutionMode(ExecutionMode::LocalSize), ..]) => {
                if let (Some(x), Some(y), Some(z)) = (w(2), w(3), w(4)) {
                    itf.local_size = Some([x, y, z]);
                }
            }
            (Op::Decorate, [Operand::IdRef(target), Operand::Decoration(d), Operand::LiteralBit32(v), ..]) => match d {
                Decoration::DescriptorSet => {
                    sets.insert(*target, *v);
                }
                Decoration::Binding => {
                    binds.insert(*target, *v);
                }
                Decoration::SpecId => itf.spec_ids.push(*v),
                Decoration::ArrayStride => {
                    strides.insert(*target, *v);
                }
                _ => {}
            },
            (
                Op::MemberDecorate,
                [Operand::IdRef(st), Operand::LiteralBit32(k), Operand::Decoration(Decoration::Offset), Operand::LiteralBit32(off)],
            ) => {
                offsets.insert((*st, *k), *off);
            }
            (Op::TypeInt | Op::TypeFloat, [Operand::LiteralBit32(bits), ..]) => {
                size.insert(id, *bits as u64 / 8);
            }
            (Op::TypeVector | Op::TypeMatrix, [Operand::IdRef(t), Operand::LiteralBit32(n)]) => {
                let s = size_of(&size, *t) * *n as u64;
                size.insert(id, s);
            }
            (Op::Constant, [Operand::LiteralBit32(v)]) => {
                consts.insert(id, *v);
            }
            (Op::Constant, [Operand::LiteralBit64(v)]) => {
                consts.insert(id, *v as u32);
            }
            (Op::TypeArray, [Operand::IdRef(t), Operand::IdRef(len)]) => {
                let n = consts.get(len).copied().unwrap_or(0) as u64;
                let stride = strides.get(&id).map(|&s| s as u64).unwrap_or_else(|| size_of(&size, *t));
                size.insert(id, n * stride);
            }
            (Op::TypeStruct, _) => {
                members.insert(id, o.iter().filter_map(word).collect());
            }
            (Op::TypePointer, [_, Operand::IdRef(t)]) => {
                pointee.insert(id, *t);
            }
            (Op::Variable, [Operand::StorageClass(StorageClass::PushConstant), ..]) => {
                let st = i.result_type.and_then(|t| pointee.get(&t).copied()).unwrap_or(0);
                let end = |(k, t): (usize, &Word)| {
                    offsets.get(&(st, k as u32)).copied().unwrap_or(0) as u64 + size_of(&size, *t)
                };
                let bytes = members.get(&st).map(|m| m.iter().enumerate().map(end).max().unwrap_or(0));
                itf.push_constant_bytes = Some(bytes.unwrap_or(0) as u32);
            }
            _ => {}
        }
    }
    let mut b: Vec<(u32, u32)> = binds.iter().map(|(id, b)| (*sets.get(id).unwrap_or(&0), *b)).collect();
    b.sort();
    itf.bindings = b;
    Ok(itf)
}

/// The capability a float-control execution mode needs.
fn mode_capability(mode: ExecutionMode) -> Capability {
    match mode {
        ExecutionMode::RoundingModeRTE => Capability::RoundingModeRTE,
        _ => Capability::SignedZeroInfNanPreserve,
    }
}

/// Adds float-control execution modes `(mode, width)` (and their capabilities) to the entry
/// point of a compiled module. glslang keeps one `spirv_execution_mode` per mode, whatever the
/// width, so the host adds them; modes already present are kept once. Without modes the module
/// is returned as it is; a module that does not load is an error (it would otherwise run
/// without the float controls its results rely on).
pub fn add_float_modes(words: &[u32], modes: &[FloatMode]) -> Result<Vec<u32>, String> {
    if modes.is_empty() {
        return Ok(words.to_vec());
    }
    let mut m = load(words)?;
    let entry = m.entry_points.first().and_then(|e| e.operands.get(1)).and_then(word);
    let Some(entry) = entry else { return Err("the module has no entry point".into()) };
    for &(mode, width) in modes {
        let cap = Operand::Capability(mode_capability(mode));
        if !m.capabilities.iter().any(|i| i.operands.first() == Some(&cap)) {
            m.capabilities.push(Instruction::new(Op::Capability, None, None, vec![cap]));
        }
        let operands = vec![Operand::IdRef(entry), Operand::ExecutionMode(mode), Operand::LiteralBit32(width)];
        if !m.execution_modes.iter().any(|i| i.operands[1..] == operands[1..]) {
            m.execution_modes.push(Instruction::new(Op::ExecutionMode, None, None, operands));
        }
    }
    Ok(m.assemble())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::shader::{compile_source, Includes};

    /// A small kernel with every part of the interface `parse_interface` reads.
    fn kernel() -> Vec<u32> {
        let src = "#version 460
layout(local_size_x = 64) in;
layout(constant_id = 7) const uint K = 1u;
layout(push_constant) uniform P { uint n; vec4 a[2]; } pc;
layout(std430, set = 0, binding = 3) buffer R { float r[]; };
void main() { r[gl_GlobalInvocationID.x] = pc.a[1].x * float(K + pc.n); }";
        compile_source("unit", "unit.comp", src, &[], &Includes::plain(), 5).unwrap()
    }

    #[test]
    fn loading_then_assembling_gives_the_same_words() {
        let w = kernel();
        assert_eq!(load(&w).unwrap().assemble(), w);
    }

    #[test]
    fn the_interface_is_read() {
        let itf = parse_interface(&kernel()).unwrap();
        assert_eq!(itf.entry_points, [(ExecutionModel::GLCompute, "main".to_string())]);
        assert_eq!(itf.local_size, Some([64, 1, 1]));
        assert_eq!(itf.bindings, [(0, 3)]);
        // `a` at byte 16, two 16-byte elements.
        assert_eq!(itf.push_constant_bytes, Some(48));
        assert_eq!(itf.spec_ids, [7]);
        assert!(itf.capabilities.contains(&Capability::Shader));
    }

    #[test]
    fn float_modes_are_added_once_with_their_capabilities() {
        let w = kernel();
        assert_eq!(add_float_modes(&w, &[]).unwrap(), w);
        let modes = [
            (ExecutionMode::RoundingModeRTE, 32),
            (ExecutionMode::SignedZeroInfNanPreserve, 32),
            (ExecutionMode::RoundingModeRTE, 16),
        ];
        let once = add_float_modes(&w, &modes).unwrap();
        // Two capabilities (two words each) and three modes (four words each), nothing else.
        assert_eq!(once.len(), w.len() + 2 * 2 + 3 * 4);
        assert_eq!(add_float_modes(&once, &modes).unwrap(), once, "modes already present are kept once");
        let m = load(&once).unwrap();
        for (mode, width) in modes {
            let want = [Operand::ExecutionMode(mode), Operand::LiteralBit32(width)];
            assert_eq!(m.execution_modes.iter().filter(|i| i.operands[1..] == want).count(), 1, "{mode:?} {width}");
        }
        for cap in [Capability::RoundingModeRTE, Capability::SignedZeroInfNanPreserve] {
            let n = m.capabilities.iter().filter(|i| i.operands[0] == Operand::Capability(cap)).count();
            assert_eq!(n, 1, "{cap:?}");
        }
    }

    #[test]
    fn a_module_that_does_not_load_says_why() {
        let w = kernel();
        let err = |w: &[u32]| parse_interface(w).unwrap_err();
        assert!(err(&w[..3]).contains("too short"), "{}", err(&w[..3]));
        let mut bad = w.clone();
        bad[0] = 0x1234_5678;
        assert!(err(&bad).contains("bad magic number 0x12345678"), "{}", err(&bad));
        // The header and the first word of a two-word OpCapability.
        assert!(err(&w[..6]).contains("truncated or malformed"), "{}", err(&w[..6]));
        let mut zero = w.clone();
        zero[5] = 0;
        assert!(err(&zero).contains("truncated or malformed"), "{}", err(&zero));
        // Without its last OpFunctionEnd: whole instructions, but a function left open.
        assert!(err(&w[..w.len() - 1]).contains("does not end with OpFunctionEnd"), "{}", err(&w[..w.len() - 1]));
        assert!(add_float_modes(&w[..6], &[(ExecutionMode::RoundingModeRTE, 32)]).is_err());
    }
}
