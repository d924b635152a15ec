//! GLSL → SPIR-V with shaderc ([`compile`], [`compile_user`]), reading and patching SPIR-V
//! ([`spirv`]: rspirv for all of it) and the checks a user's module passes
//! before it stands in for a built-in kernel ([`check`]).
//!
//! Includes resolve, in order, to: `interface.glsl` (generated for the variant from the Rust
//! definitions, see [`crate::interface`]), `layout.glsl` (the variant's layout hooks),
//! `layout/<name>.glsl` (any registered layout's hooks), the shared files of `glsl/`
//! (embedded, so the binary is self-contained), and — for a user's kernel — files beside it.

pub mod check;
pub mod spirv;

pub use check::{check_user, validate, validate_user};
pub use spirv::{parse_interface, read_spirv, Interface};

use super::GpuError;
use crate::interface;
use crate::layout::LayoutId;
use crate::variant::{DeviceBuild, KernelId, Variant};
use std::path::{Path, PathBuf};

/// The shared GLSL sources: every file directly in `glsl/` (layout hooks come from the
/// registry), embedded by `build.rs` so a new shared header needs no list here.
pub const SOURCES: &[(&str, &str)] = include!(concat!(env!("OUT_DIR"), "/glsl_sources.rs"));

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
        Includes { interface: v.interface_glsl(), layout: Some(v.layout.info().glsl), user_dir: None }
    }

    /// The includes of a kernel without a layout (the ray-query baseline, the arithmetic rates).
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
            if let Ok(l) = LayoutId::parse(name) {
                return Ok(l.info().glsl.to_string());
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

/// Compiles one built-in kernel for a device offering `dev`.
pub fn compile(k: &KernelId, dev: DeviceBuild) -> Result<Vec<u32>, GpuError> {
    compile_builtin(k, dev, None)
}

/// The built-in kernel `k` with its named branches marked (`BRANCH_MARKS`,
/// [`crate::variant::Source::Marked`]).
pub fn compile_marked(k: &KernelId, dev: DeviceBuild) -> Result<Vec<u32>, GpuError> {
    compile_builtin(k, dev, Some(("BRANCH_MARKS", "branches marked")))
}

/// The built-in counting kernel `k` with its named branches counted (`BRANCH_COUNTS`,
/// [`crate::variant::Source::Counted`]).
pub fn compile_counted(k: &KernelId, dev: DeviceBuild) -> Result<Vec<u32>, GpuError> {
    if !k.stats {
        return Err(GpuError::Other(format!("{}: the branch-counting build is a counting kernel", k.name())));
    }
    compile_builtin(k, dev, Some(("BRANCH_COUNTS", "branches counted")))
}

/// `extra`: a define and what it makes of the kernel (in its name).
fn compile_builtin(k: &KernelId, dev: DeviceBuild, extra: Option<(&str, &str)>) -> Result<Vec<u32>, GpuError> {
    let src = source("trav.comp").expect("glsl/trav.comp is embedded");
    let v = &k.variant;
    let mut defines = v.defines(k.imp, k.stats, dev);
    let mut name = k.name();
    if let Some((define, what)) = extra {
        defines.push((define.into(), "1".into()));
        name += &format!(" ({what})");
    }
    let words = compile_source(&name, "trav.comp", src, &defines, &Includes::variant(v), dev.spirv_minor)?;
    with_float_modes(&name, &words, v)
}

/// `words` with the float-control modes of `v` added ([`spirv::add_float_modes`]).
fn with_float_modes(name: &str, words: &[u32], v: &Variant) -> Result<Vec<u32>, GpuError> {
    spirv::add_float_modes(words, &super::support::float_modes(v))
        .map_err(|e| GpuError::Compile { variant: name.to_string(), log: format!("adding float controls: {e}") })
}

/// Compiles a user's GLSL kernel file with the defines and includes of the built-in kernel
/// `k` (plus the file's own folder).
pub fn compile_user(path: &Path, k: &KernelId, dev: DeviceBuild) -> Result<Vec<u32>, GpuError> {
    let v = &k.variant;
    let src = std::fs::read_to_string(path)
        .map_err(|e| GpuError::Spirv { path: path.display().to_string(), msg: format!("cannot read: {e}") })?;
    let mut inc = Includes::variant(v);
    inc.user_dir = path.parent().map(Path::to_path_buf);
    let file = path.file_name().map(|f| f.to_string_lossy().to_string()).unwrap_or_default();
    let defines = v.defines(k.imp, k.stats, dev);
    let name = format!("{} ({})", k.name(), path.display());
    let words = compile_source(&name, &file, &src, &defines, &inc, dev.spirv_minor)?;
    with_float_modes(&name, &words, v)
}

/// Compiles a shared kernel without a layout (`trav_rq.comp`, `arith.comp`, the ray-tracing
/// stages `trav_rt.rgen`, `.rchit`, `.rmiss`), with defines.
pub fn compile_plain(name: &str, file: &str, defines: &[(String, String)]) -> Result<Vec<u32>, GpuError> {
    let src = source(file)
        .ok_or_else(|| GpuError::Compile { variant: name.into(), log: format!("missing source {file}") })?;
    compile_source(name, file, src, defines, &Includes::plain(), 5)
}

/// The shader stage of a source file, by its extension.
fn stage(file: &str) -> shaderc::ShaderKind {
    match Path::new(file).extension().and_then(|e| e.to_str()) {
        Some("rgen") => shaderc::ShaderKind::RayGeneration,
        Some("rchit") => shaderc::ShaderKind::ClosestHit,
        Some("rmiss") => shaderc::ShaderKind::Miss,
        _ => shaderc::ShaderKind::Compute,
    }
}

/// Compiles GLSL source with defines into SPIR-V 1.`spirv_minor` (5: for Vulkan 1.2; 3: Vulkan
/// 1.1; 0: Vulkan 1.0); `#include`s resolve through `inc`. The stage is the file's extension's
/// (glslang's: `.rgen`, `.rchit`, `.rmiss`), compute for anything else.
pub fn compile_source(
    name: &str,
    file: &str,
    src: &str,
    defines: &[(String, String)],
    inc: &Includes,
    spirv_minor: u8,
) -> Result<Vec<u32>, GpuError> {
    let compile_err = |log: String| GpuError::Compile { variant: name.to_string(), log };
    let compiler = shaderc::Compiler::new().map_err(|e| compile_err(format!("shaderc unavailable: {e}")))?;
    let mut opts = shaderc::CompileOptions::new().map_err(|e| compile_err(format!("shaderc options: {e}")))?;
    let (env, spirv) = match spirv_minor {
        0 => (shaderc::EnvVersion::Vulkan1_0, shaderc::SpirvVersion::V1_0),
        1..=4 => (shaderc::EnvVersion::Vulkan1_1, shaderc::SpirvVersion::V1_3),
        _ => (shaderc::EnvVersion::Vulkan1_2, shaderc::SpirvVersion::V1_5),
    };
    opts.set_target_env(shaderc::TargetEnv::Vulkan, env as u32);
    opts.set_target_spirv(spirv);
    opts.set_optimization_level(shaderc::OptimizationLevel::Performance);
    for (k, val) in defines {
        opts.add_macro_definition(k, Some(val));
    }
    opts.set_include_callback(|req, _ty, _from, _depth| {
        inc.resolve(req).map(|content| shaderc::ResolvedInclude { resolved_name: req.to_string(), content })
    });
    let art = compiler
        .compile_into_spirv(src, stage(file), file, "main", Some(&opts))
        .map_err(|e| compile_err(e.to_string()))?;
    Ok(art.as_binary().to_vec())
}

#[cfg(test)]
mod tests {
    use super::SOURCES;
    use crate::layout::LayoutId;

    /// The bodies of the `[[unroll]]` loops of GLSL source `src` (comments removed first): after
    /// the loop's parenthesised header, its `{…}` block, or its single statement up to `;`.
    fn unrolled_bodies(src: &str) -> Vec<String> {
        let mut code = String::new();
        let mut rest = src;
        while let Some(at) = rest.find("/*") {
            code.push_str(&rest[..at]);
            rest = rest[at..].find("*/").map_or("", |e| &rest[at + e + 2..]);
        }
        code.push_str(rest);
        let code: String = code.lines().map(|l| l.split("//").next().unwrap_or("")).collect::<Vec<_>>().join("\n");
        // The end (exclusive) of the balanced `open`…`close` group starting at byte `from`.
        let group_end = |from: usize, open: char, close: char| {
            let mut depth = 0usize;
            for (i, ch) in code[from..].char_indices() {
                if ch == open {
                    depth += 1;
                } else if ch == close {
                    depth -= 1;
                    if depth == 0 {
                        return Some(from + i + ch.len_utf8());
                    }
                }
            }
            None
        };
        let mut out = Vec::new();
        for (at, _) in code.match_indices("[[unroll]]") {
            let Some(header) = code[at..].find('(').map(|o| at + o) else { continue };
            let Some(body) = group_end(header, '(', ')') else { continue };
            let start = body + code[body..].len() - code[body..].trim_start().len();
            let end = if code[start..].starts_with('{') {
                group_end(start, '{', '}')
            } else {
                code[start..].find(';').map(|e| start + e + 1)
            };
            if let Some(end) = end {
                out.push(code[start..end].to_string());
            }
        }
        out
    }

    /// No `continue` in an `[[unroll]]` loop of any kernel source or layout hook: Mesa's NIR does
    /// not unroll such a loop and lowers the continue with flags that read the previous
    /// iteration's values, which then live across the whole traversal loop (Mali-G610, f32 at
    /// B = 4: 47 spills and fills with the continues, 6 without; see docs/architecture.md).
    #[test]
    fn no_unrolled_loop_continues() {
        let mut files: Vec<(String, &str)> = SOURCES.iter().map(|(n, s)| (n.to_string(), *s)).collect();
        files.extend(LayoutId::all().map(|l| (format!("layout/{}.glsl", l.name()), l.info().glsl)));
        let mut bodies = 0;
        for (name, src) in &files {
            for body in unrolled_bodies(src) {
                bodies += 1;
                assert!(!body.contains("continue"), "{name}: an [[unroll]] loop continues:\n{body}");
            }
        }
        assert!(bodies >= 8, "only {bodies} [[unroll]] loops found: the scan is broken");
        // The scan finds what it looks for: a block, a single statement, not a comment.
        let block = unrolled_bodies("[[unroll]] for (uint s = 0u; s < 4u; s++) { if (x) { continue; } }\n");
        assert!(block.len() == 1 && block[0].contains("continue"), "{block:?}");
        let single = unrolled_bodies("[[unroll]] for (int a = 0; a < 3; a++) if (x) continue;\n{ y(); }");
        assert!(single.len() == 1 && single[0].contains("continue") && !single[0].contains("y()"), "{single:?}");
        let commented = unrolled_bodies("/* [[unroll]] for (;;) { continue; } */ // [[unroll]] for (;;) {}\n");
        assert!(commented.is_empty(), "{commented:?}");
    }
}
