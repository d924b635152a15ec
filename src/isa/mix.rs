//! The instruction mix of the other vendors' disassembly, in the counts AMD's has
//! ([`crate::isa::counts`]): instructions; ALU instructions (neither memory nor control flow),
//! of which fp16 packed two to a register, fp16 unpacked, fp32 and conversions; private-memory
//! (spill) loads and stores where the ISA names them.
//!
//! - Adreno (ir3, turnip's "IR3 assembly"): an ALU op's precision is its type suffix (`.f16`,
//!   `.f32`) or, for the generic `.f` ops, its destination register (`hr` half, `r` full; a
//!   compare: its first source). ir3 has no packed fp16. `ldp`/`stp` are private memory.
//! - NVIDIA (NAK's listing): `hadd2`, `hmul2`, `hfma2`, `hmnmx2`, `hset(p)2` are packed fp16 (the
//!   only fp16 ALU there is); `fadd`, `fmul`, `ffma`, `fmnmx`, `fset(p)`, `fswzadd`, `mufu` fp32;
//!   `f2f`, `f2i`, `i2f`, `f2fp` conversions; `ld.local`/`st.local` private memory.
//! - Intel (anv's "GEN assembly"): an ALU op's precision is its destination type (`HF` fp16,
//!   `F` fp32); a `mov` between types is a conversion. Intel has no packed fp16 instruction
//!   (fp16 runs wider SIMD); spills go through `send`s the text does not tell apart.
//! - Mali Valhall and Bifrost (panvk's "Assembly"): `.v2f16` is packed fp16, `.f16` unpacked,
//!   `.f32` fp32; `X_TO_Y` converts; `LOAD`/`STORE` through `thread_local_pointer` are private
//!   memory.

use crate::report::isa::AsmCounts;

/// Which ISA a disassembly is: each vendor's file names its own ([`crate::vendor::Vendor::disassembly`]).
pub use crate::vendor::Disassembly as Isa;

#[derive(Clone, Copy, PartialEq, Eq)]
enum Class {
    Packed16,
    Scalar16,
    F32,
    Conversion,
    OtherAlu,
    PrivateLoad,
    PrivateStore,
    NotAlu,
}

fn add(c: &mut AsmCounts, class: Class) {
    c.instructions += 1;
    match class {
        Class::PrivateLoad => *c.scratch_loads.get_or_insert(0) += 1,
        Class::PrivateStore => *c.scratch_stores.get_or_insert(0) += 1,
        Class::NotAlu => {}
        alu => {
            c.valu += 1;
            match alu {
                Class::Packed16 => c.packed_f16 += 1,
                Class::Scalar16 => c.scalar_f16 += 1,
                Class::F32 => c.f32 += 1,
                Class::Conversion => c.conversions += 1,
                _ => {}
            }
        }
    }
}

/// Counts the instructions of disassembly `text` in ISA `isa` (ACO's as a GFX9+ generation's,
/// with `scratch_*` instructions: [`crate::isa::counts`] takes the generation).
pub fn count(isa: Isa, text: &str) -> AsmCounts {
    let mut c = AsmCounts::default();
    if isa == Isa::Aco {
        return crate::isa::counts::count(text, true);
    }
    if matches!(isa, Isa::Ir3 | Isa::Nak | Isa::Mali) {
        // These ISAs name private memory: zero is a count, not "unknown".
        (c.scratch_loads, c.scratch_stores) = (Some(0), Some(0));
    }
    for line in text.lines() {
        let class = match isa {
            Isa::Ir3 => ir3(line),
            Isa::Nak => nak(line),
            Isa::Intel => intel(line),
            Isa::Mali => mali(line),
            Isa::Aco => None,
        };
        if let Some(k) = class {
            add(&mut c, k);
        }
    }
    c
}

/// Leading `(flags)` of an ir3 instruction (`(ss)(rpt2)nop`, `(jp)br …`) removed.
fn strip_ir3_flags(mut s: &str) -> &str {
    loop {
        s = s.trim_start();
        match s.strip_prefix('(').and_then(|r| r.split_once(')')) {
            Some((_, rest)) => s = rest,
            None => return s,
        }
    }
}

fn ir3(line: &str) -> Option<Class> {
    let s = strip_ir3_flags(line);
    let (m, ops) = s.split_once(char::is_whitespace).unwrap_or((s, ""));
    if m.is_empty() || m.ends_with(':') || !m.starts_with(|c: char| c.is_ascii_lowercase()) || s.starts_with(';') {
        return None;
    }
    let base = m.split('.').next().unwrap_or(m);
    Some(match base {
        "ldp" => Class::PrivateLoad,
        "stp" => Class::PrivateStore,
        "cov" => {
            let t = m.split('.').nth(1).unwrap_or("");
            if t.contains('f') {
                Class::Conversion
            } else {
                Class::OtherAlu
            }
        }
        "nop" | "br" | "brac" | "brax" | "jump" | "end" | "ret" | "kill" | "demote" | "predt" | "predf" | "prede"
        | "shps" | "shpe" | "chmask" | "chsh" | "getone" | "getlast" | "bar" | "fence" | "andg" | "bany" | "ball"
        | "flow_rev" => Class::NotAlu,
        b if b.starts_with("ld")
            || b.starts_with("st")
            || b.starts_with("isam")
            || b.starts_with("sam")
            || b.starts_with("atomic")
            || b.starts_with("resinfo")
            || b == "resfmt"
            || b == "stib"
            || b == "ldib" =>
        {
            Class::NotAlu
        }
        _ => {
            let parts: Vec<&str> = m.split('.').collect();
            let float = parts.iter().skip(1).any(|p| p.starts_with('f'));
            if !float {
                Class::OtherAlu
            } else if m.contains(".f16") {
                Class::Scalar16
            } else if m.contains(".f32") {
                Class::F32
            } else {
                // Generic `.f`: the destination's register file, or a compare's first source.
                let regs: Vec<&str> = ops.split(',').map(|o| o.trim()).collect();
                let r = if base == "cmps" || base == "cmpv" { regs.get(1) } else { regs.first() };
                let r = r.map(|r| strip_ir3_flags(r.trim_start_matches('-'))).unwrap_or("");
                if r.starts_with("hr") || r.starts_with("hc") {
                    Class::Scalar16
                } else {
                    Class::F32
                }
            }
        }
    })
}

fn nak(line: &str) -> Option<Class> {
    let body = line.split("//").next()?.trim();
    if body.is_empty() || body.starts_with("block") || body.starts_with('}') || body.starts_with('{') {
        return None;
    }
    // `@!p5 bra L0`, `r1 = fadd r2 r3`, `p4 null = plop3 …`
    let body = match body.split_once(" = ") {
        Some((_, rhs)) => rhs.trim(),
        None => body.trim_start_matches(|c: char| c != ' ' && body.starts_with('@')).trim(),
    };
    let m = body.split_whitespace().next()?;
    let base = m.split('.').next()?;
    Some(match base {
        "hadd2" | "hmul2" | "hfma2" | "hmnmx2" | "hsetp2" | "hset2" => Class::Packed16,
        "fadd" | "fmul" | "ffma" | "fmnmx" | "fsetp" | "fset" | "fswzadd" | "mufu" | "fsel" | "frnd" => Class::F32,
        "f2f" | "f2i" | "i2f" | "f2fp" | "i2fp" => Class::Conversion,
        "ld" | "st" if m.contains(".local") => {
            if base == "ld" {
                Class::PrivateLoad
            } else {
                Class::PrivateStore
            }
        }
        "ld" | "st" | "ldc" | "lds" | "sts" | "ldg" | "stg" | "atom" | "atoms" | "red" | "suld" | "sust" | "tex"
        | "tld" | "txq" | "ipa" | "ald" | "ast" | "al2p" | "membar" | "ccctl" => Class::NotAlu,
        "bra" | "bssy" | "bsync" | "bclear" | "bmov" | "brk" | "cont" | "exit" | "nop" | "bar" | "warpsync"
        | "kill" | "sync" | "cs2r" | "s2r" | "yld" => Class::NotAlu,
        _ => Class::OtherAlu,
    })
}

fn intel(line: &str) -> Option<Class> {
    let s = line.trim();
    // `(+f0.0) sel(16) g19<1>UD …`, `math inv(16) g83<1>HF …`, `mov(16) g30<2>HF g69<8,8,1>F`
    let s = if s.starts_with('(') { s.split_once(')').map(|(_, r)| r.trim())? } else { s };
    let open = s.find('(')?;
    let m = s[..open].trim();
    if m.is_empty()
        || !m.starts_with(|c: char| c.is_ascii_lowercase())
        || m.contains(' ') && !(m.starts_with("math") || m.starts_with("sync"))
    {
        return None;
    }
    let base = m.split(['.', ' ']).next()?;
    let rest = &s[open..];
    // Types after each region: `<1>HF`, `<8,8,1>F`, immediates `0x3f800000F`.
    let types: Vec<&str> = rest
        .split('>')
        .skip(1)
        .map(|t| t.split(|c: char| !c.is_ascii_alphabetic()).next().unwrap_or(""))
        .filter(|t| !t.is_empty())
        .collect();
    let dst = types.first().copied().unwrap_or("");
    Some(match base {
        "send" | "sends" | "sendc" | "sendsc" => Class::NotAlu,
        "if" | "else" | "endif" | "while" | "break" | "cont" | "halt" | "jmpi" | "call" | "calla" | "ret" | "goto"
        | "join" | "sync" | "nop" | "wait" => Class::NotAlu,
        "mov" if types.len() >= 2 && types[0] != types[1] && (is_float(types[0]) || is_float(types[1])) => {
            Class::Conversion
        }
        _ if dst == "HF" => Class::Scalar16,
        _ if dst == "F" => Class::F32,
        _ => Class::OtherAlu,
    })
}

fn is_float(t: &str) -> bool {
    matches!(t, "F" | "HF" | "DF" | "BF")
}

fn mali(line: &str) -> Option<Class> {
    let s = line.trim();
    let m = s.split_whitespace().next()?;
    if !m.starts_with(|c: char| c.is_ascii_uppercase()) || m.ends_with(':') {
        return None;
    }
    let base = m.split('.').next()?;
    Some(if (base == "LOAD" || base.starts_with("LOAD")) && s.contains("thread_local_pointer") {
        Class::PrivateLoad
    } else if base.starts_with("STORE") && s.contains("thread_local_pointer") {
        Class::PrivateStore
    } else if base.starts_with("LOAD")
        || base.starts_with("STORE")
        || base.starts_with("LD_")
        || base.starts_with("ST_")
        || base.starts_with("LEA_")
        || base.starts_with("ATOM")
        || base.starts_with("TEX")
        || base.starts_with("VAR_")
        || base.starts_with("BRANCH")
        || base.starts_with("JUMP")
        || base == "NOP"
        || base == "BARRIER"
        || base == "DISCARD"
    {
        Class::NotAlu
    } else if base.contains("_TO_") {
        Class::Conversion
    } else if m.contains(".v2f16") {
        Class::Packed16
    } else if m.contains(".f16") {
        Class::Scalar16
    } else if m.contains(".f32") {
        Class::F32
    } else {
        Class::OtherAlu
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ir3_lines() {
        let t = "l187:\n(jp)(rpt2)nop\nadd.f r17.z, r17.y, r18.x\nadd.f hr1.x, hr2.y, hr3.z\nmad.f16 hr0.x, hr1.x, hr1.y, hr2.x\n\
                 cmps.f.ge hr0.z, (abs)r15.x, (abs)r15.z\ncov.f32f16 hr4.x, r4.x\nldp.u32 r15.w, p[r0.w+500], 4\n\
                 stp.u32 p[r0.w+8], r1.x, 1\nadd.u r19.z, r19.z, -22\nbr !p0.z, #l325\n";
        let c = count(Isa::Ir3, t);
        assert_eq!((c.instructions, c.valu, c.f32, c.scalar_f16, c.conversions), (10, 6, 2, 2, 1));
        assert_eq!((c.scratch_loads, c.scratch_stores, c.packed_f16), (Some(1), Some(1), 0));
    }

    #[test]
    fn nak_lines() {
        let t = "block 5 L10 [4] -> {\n      p5        = fsetp.ge.ftz r95 r96 // delay=7\n      r1 = hfma2 r2 r3 r4 // d\n\
                 @p5               bra L8 // delay=1\n      r2 = ld.local.strong.cta.b32 [r1] // d\n\
                 st.local.b32 [r1] r2 // d\n      r3 = f2f.f32.f16 r4 // d\n      r98 = iadd3 r97 0x1 rZ // d\n} -> [7]\n";
        let c = count(Isa::Nak, t);
        assert_eq!((c.instructions, c.valu, c.f32, c.packed_f16, c.conversions), (7, 4, 1, 1, 1));
        assert_eq!((c.scratch_loads, c.scratch_stores), (Some(1), Some(1)));
    }

    #[test]
    fn intel_lines() {
        let t = "START B0 (42 cycles)\nmov(16)         g30<2>HF        g69<8,8,1>F                     { align1 1H F@3 };\n\
                 math inv(16)    g83<1>HF        g82<16,16,1>HF  null<8,8,1>HF   { align1 1H I@1 };\n\
                 add(16)         g16<1>D         -g13<8,8,1>D    9D              { align1 1H };\n\
                 (+f0.0) sel(16) g19<1>UD        g16<1,1,0>UD    g2<1,1,0>UD     { align1 1H I@2 compacted };\n\
                 mul(16)         g26<1>F         g25<1,1,0>F     0x4b000000F  /* 8.38861e+06F */ { align1 1H compacted };\n\
                 send(16)        g4UD            g2UD            nullUD          0x04440000  0x00000000\n\
                 sync nop(1)                     null<0,1,0>UB                   { align1 WE_all 1N F@7 };\n\
                 endif(16)       JIP:  LABEL1                                 { align1 1H };\n";
        let c = count(Isa::Intel, t);
        assert_eq!((c.instructions, c.valu, c.conversions, c.scalar_f16, c.f32), (8, 5, 1, 1, 1));
        assert_eq!(c.scratch_loads, None);
    }

    #[test]
    fn mali_lines() {
        let t = "   LOAD.i32.unsigned.slot1.wait1 @r5, thread_local_pointer.w0, offset:3568\n   FRCP.f32 r5, ^r5\n\
                 STORE.i32.force.slot2.wait2 @r5, thread_local_pointer.w0, offset:3680\n   FADD.v2f16 r1, r2, r3\n\
                 FMA.f16 r1, r2, r3, r4\n   F16_TO_F32 r4, r5\n   IADD_IMM.i32 r6, 0x0, #0x80000000\n\
                 BRANCHZ.eq.reconverge r8.h0, offset:3\n   LD_BUFFER.i32 r1, r2\n";
        let c = count(Isa::Mali, t);
        assert_eq!((c.instructions, c.valu, c.f32, c.packed_f16, c.scalar_f16, c.conversions), (9, 5, 1, 1, 1, 1));
        assert_eq!((c.scratch_loads, c.scratch_stores), (Some(1), Some(1)));
    }
}
