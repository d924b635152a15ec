//! The instruction mix of an AMD disassembly (RADV's "Assembly" representation, LLVM's
//! syntax): vector ALU instructions split into packed fp16, scalar fp16, fp32 and
//! conversions; scratch loads and stores; what the disassembler could not decode.
//!
//! A conversion is a `v_cvt_*`, or ACO's other spelling of one: a mixed-precision fma
//! (`v_fma_mix_f32`, `v_fma_mixlo_f16`, `v_fma_mixhi_f16`) by `1.0` plus a zero, which is
//! exactly the conversion of its other source (1·x + (−0) = x, signed zeros kept), and which
//! ACO emits on GFX9+ to write one half of a register or read one.

use crate::report::isa::AsmCounts;

/// One operation: its mnemonic and the text of its operands.
#[derive(Clone)]
struct Op {
    mnemonic: String,
    operands: String,
}

/// One instruction of operations `ops` (two for a dual-issue one): one vector ALU
/// instruction if any is one, as the driver counts them, each operation classified.
fn instruction(c: &mut AsmCounts, ops: &[Op], flat_scratch: bool) {
    c.instructions += 1;
    if ops.is_empty() {
        c.undecoded += 1;
    }
    if ops.iter().any(|o| o.mnemonic.starts_with("v_")) {
        c.valu += 1;
    }
    for o in ops {
        op(c, o, flat_scratch);
    }
}

/// A mixed-precision fma that only converts: one multiplicand `1.0`, the addend a zero. The
/// sources are the last three operands in both syntaxes (LLVM's lists the destination first,
/// ACO's before ` = `); modifiers after them (`op_sel…`, `clamp`) are dropped.
fn is_mix_conversion(o: &Op) -> bool {
    if !o.mnemonic.starts_with("v_fma_mix") {
        return false;
    }
    let text = o.operands.split(" op_sel").next().unwrap_or("").split(" clamp").next().unwrap_or("");
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [.., a, b, addend] = parts[..] else { return false };
    let zero = addend
        .replace(['(', ')', '-'], "")
        .trim_start_matches("neg")
        .trim_start_matches("lo")
        .trim_start_matches("hi")
        .to_string();
    (a == "1.0" || b == "1.0") && (zero == "0" || zero == "0.0")
}

/// One operation's class.
fn op(c: &mut AsmCounts, o: &Op, flat_scratch: bool) {
    let m = o.mnemonic.as_str();
    if let Some(rest) = m.strip_prefix("v_") {
        // Packed: v_pk_*_f16, and the dot products of fp16 pairs (v_dot2_f32_f16, …).
        if (rest.starts_with("pk_") || rest.starts_with("dot2")) && m.contains("_f16") {
            c.packed_f16 += 1;
        } else if rest.starts_with("cvt_") || is_mix_conversion(o) {
            c.conversions += 1;
        } else if m.contains("_f16") {
            c.scalar_f16 += 1;
        } else if m.contains("_f32") {
            c.f32 += 1;
        }
    } else if flat_scratch && m.starts_with("scratch_load") {
        *c.scratch_loads.get_or_insert(0) += 1;
    } else if flat_scratch && m.starts_with("scratch_store") {
        *c.scratch_stores.get_or_insert(0) += 1;
    }
}

/// Counts the instructions of `asm`. `flat_scratch`: the generation has `scratch_*`
/// instructions (GFX9 on); before it scratch goes through buffer instructions that the text
/// does not tell from other buffer accesses, so the scratch counts stay `None`.
///
/// Two syntaxes: LLVM's disassembly (`\tv_mul_f32_e32 v1, v2, v3 ; 10020702`) and, where
/// Mesa's LLVM cannot disassemble the generation (RDNA4 with LLVM 15), ACO's own listing of
/// the final hardware instructions (`\t v1: %8:v[0] = v_lshl_add_u32 …`). An instruction is
/// an indented line that is not a comment; its mnemonic is its first word, after the
/// definitions (`… = `) in ACO's syntax. `(then repeated N times)` repeats the instruction
/// before it N more times; `(invalid instruction)` is one undecoded instruction; a dual-issue
/// line (`v_dual_a … :: v_dual_b …`) is one vector ALU instruction (as the driver's VALU
/// statistic counts it) whose two operations are classified each. Headers
/// and block labels (`BB3:`, `BB3`) are not indented and are not counted.
pub fn count(asm: &str, flat_scratch: bool) -> AsmCounts {
    let mut c = AsmCounts {
        scratch_loads: flat_scratch.then_some(0),
        scratch_stores: flat_scratch.then_some(0),
        ..AsmCounts::default()
    };
    let mut last: Option<Vec<Op>> = None;
    for line in asm.lines() {
        let indented = line.starts_with([' ', '\t']);
        let code = line.split(';').next().unwrap_or("").trim();
        if let Some(n) = code.strip_prefix("(then repeated ").and_then(|r| r.strip_suffix(" times)")) {
            let n: u64 = n.trim().parse().unwrap_or(0);
            if let Some(ops) = &last {
                for _ in 0..n {
                    instruction(&mut c, ops, flat_scratch);
                }
            }
            continue;
        }
        if code.starts_with("(invalid instruction)") {
            instruction(&mut c, &[], flat_scratch);
            last = Some(Vec::new());
            continue;
        }
        if !indented || code.is_empty() || code.starts_with("//") || code.starts_with("/*") {
            continue;
        }
        let ops: Vec<Op> = code
            .split("::")
            .filter_map(|part| {
                let part = match part.find(" = ") {
                    Some(i) if part[..i].contains(':') => &part[i + 3..],
                    _ => part,
                };
                let part = part.trim();
                let m = part.split_whitespace().next()?;
                Some(Op {
                    mnemonic: m.strip_prefix("v_dual_").map(|r| format!("v_{r}")).unwrap_or_else(|| m.to_string()),
                    operands: part[m.len()..].trim().to_string(),
                })
            })
            .collect();
        instruction(&mut c, &ops, flat_scratch);
        last = Some(ops);
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed snippet in RADV's format, every rule exercised once.
    #[test]
    fn counts_a_fixed_snippet() {
        let asm = "BB0:\n\
            \ts_mul_i32 s14, s14, s10                                     ; 960e0a0e\n\
            \tv_pk_fma_f16 v1, v2, v3, v4                                 ; cc0e4001 04120702\n\
            \tv_pk_max_f16 v5, v5, v6                                     ; cc124005 18020d05\n\
            \tv_pk_add_u16 v7, v7, v8                                     ; cc0a4007 18021107\n\
            \tv_mul_f16_e32 v9, v9, v10                                   ; 6a121509\n\
            \tv_cmp_ge_f16_e64 s[0:1], v1, v2                             ; d4060000 00020501\n\
            \tv_cvt_f32_f16_e32 v3, v3                                    ; 7e061703\n\
            \tv_min_f32_e32 v4, v4, v5                                    ; 1e080b04\n\
            (then repeated 2 times)\n\
            \tv_dual_mul_f32 v1, v2, v3 :: v_dual_add_f16 v4, v5, v6      ; c8c60702 04040b05\n\
            \tv_mov_b32_e32 v0, 0                                         ; 7e000280\n\
            (invalid instruction)                                        ; 7e463880\n\
            (then repeated 1 times)\n\
            \tscratch_store_b32 off, v40, s0 offset:4                     ; dc690004 00002800\n\
            \tscratch_load_b128 v[4:7], off, s0                           ; dc5c0000 04000000\n\
            \tbuffer_load_b128 v[4:7], v1, s[12:15], 0 offen              ; e05c0000 80430401\n\
            BB1:\n\
            \ts_endpgm                                                    ; bfb00000\n";
        let c = count(asm, true);
        let want = AsmCounts {
            instructions: 18,
            valu: 11,
            packed_f16: 2,
            scalar_f16: 3,
            f32: 4,
            conversions: 1,
            scratch_loads: Some(1),
            scratch_stores: Some(1),
            undecoded: 2,
        };
        assert_eq!(c, want);
        assert_eq!(c.packed_share(), Some(0.4));
        // ACO's listing of the same kind of code (RDNA4 where LLVM cannot disassemble it).
        let aco = "Shader disassembly is not supported in the current configuration, falling back to print_program.\n\
            \n\
            After lowering to hw instructions:\n\
            ACO shader stage: SW (CS), HW (COMPUTE_SHADER)\n\
            BB0\n\
            /* logical preds: / linear preds: / kind: top-level, branch, */\n\
            \t s1: (SzInfNaNPreserve)%3:s[10] = s_mul_i32 %1107:s[115], %1101:s[10]\n\
            \ts_delay_alu salu_cycle_1 next salu_cycle_1\n\
            \t v1: %29:v[9] = v_pk_fma_f16 %1:v[1], %2:v[2], %3:v[3]\n\
            \t s2: (precise)%25:s[0-1] = v_cmp_gt_f16 0x800000, |%1125:v[8]|\n\
            \t v1: %26:v[8] = v_cndmask_b32 %1125:v[8], 0, %25:s[0-1]\n\
            \t v1: %30:v[4] = v_cvt_f32_f16 %29:v[9]\n\
            \tscratch_store_dword %0:v[0], %1:s[0], %40:v[40] offset:4\n\
            BB1\n\
            \ts_endpgm\n";
        let want = AsmCounts {
            instructions: 8,
            valu: 4,
            packed_f16: 1,
            scalar_f16: 1,
            f32: 0,
            conversions: 1,
            scratch_loads: Some(0),
            scratch_stores: Some(1),
            undecoded: 0,
        };
        assert_eq!(count(aco, true), want);
        // Without flat scratch (GCN1–4), the scratch counts are unknown, not zero.
        let old = count(asm, false);
        assert_eq!((old.scratch_loads, old.scratch_stores, old.valu), (None, None, 11));
    }

    /// ACO's conversions spelled as mixed-precision fmas (1·x + 0) count as conversions, in
    /// both syntaxes; a mixed fma that computes something stays scalar fp16 or fp32.
    #[test]
    fn mix_fmas_by_one_plus_zero_are_conversions() {
        let asm = "\tv_fma_mixlo_f16 v13, 1.0, v12, neg(0) op_sel_hi:[0,0,1]     ; cc21400d 820218f2\n\
            \tv_fma_mix_f32 v66, -v70, 1.0, neg(0) op_sel_hi:[1,0,0]      ; cc200042 aa01e546\n\
            \tv_fma_mixhi_f16 v13, v12, 1.0, 0 op_sel_hi:[0,0,1]          ; cc22400d 82020d0c\n\
            \tv_fma_mixlo_f16 v13, v1, v12, v2 op_sel_hi:[0,0,1]          ; cc21400d 040a1901\n\
            \tv_fma_mix_f32 v66, v70, 1.0, v3 op_sel_hi:[1,0,0]           ; cc200042 040de546\n\
            \t v2b: (SzInfNaNPreserve)%413:v[13][0:16] = v_fma_mixlo_f16 1.0, %409:v[12], neg(lo(0))\n\
            \t v2b: %414:v[14][0:16] = v_fma_mixlo_f16 %1:v[1], %409:v[12], %2:v[2]\n";
        let c = count(asm, true);
        assert_eq!((c.instructions, c.valu), (7, 7));
        assert_eq!((c.conversions, c.scalar_f16, c.f32), (4, 2, 1), "{c:?}");
    }
}
