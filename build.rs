//! Links glslang and SPIRV-Tools statically: Debian's `libshaderc_combined.a` does not contain
//! them, and its `libshaderc.so` does not link with lld. Embeds every shared GLSL source of
//! `glsl/` (`gpu::shader::SOURCES`), so a new shared header needs no list in the code.
fn main() {
    embed_glsl();
    let dir = std::env::var("SHADERC_LIB_DIR").unwrap_or_else(|_| "/usr/lib/x86_64-linux-gnu".into());
    println!("cargo:rustc-link-search=native={dir}");
    for lib in [
        "glslang",
        "MachineIndependent",
        "GenericCodeGen",
        "OSDependent",
        "OGLCompiler",
        "SPIRV",
        "SPIRV-Tools-opt",
        "SPIRV-Tools",
        "glslang-default-resource-limits",
    ] {
        println!("cargo:rustc-link-lib=static={lib}");
    }
    println!("cargo:rustc-link-lib=dylib=stdc++");
    println!("cargo:rerun-if-env-changed=SHADERC_LIB_DIR");
    println!("cargo:rerun-if-changed=build.rs");
    // The commit goes into every report row.
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_else(|| "unknown".into());
    let dirty = std::process::Command::new("git")
        .args(["status", "--porcelain", "--untracked-files=no"])
        .output()
        .ok()
        .is_some_and(|o| !o.stdout.is_empty());
    println!("cargo:rustc-env=HALFTRACE_COMMIT={commit}{}", if dirty { "-dirty" } else { "" });
    println!("cargo:rerun-if-changed=.git/HEAD");
    println!("cargo:rerun-if-changed=.git/index");
}

/// Writes `$OUT_DIR/glsl_sources.rs`: `&[(file name, include_str!(path)), …]` for every
/// `.glsl`, `.comp` and ray-tracing stage (`.rgen`, `.rchit`, `.rmiss`) file directly in
/// `glsl/` (the layout hooks in `glsl/layout/` come from the registry), sorted.
fn embed_glsl() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(&dir)
        .expect("glsl/ beside Cargo.toml")
        .map(|e| e.expect("readable glsl/ entry").path())
        .filter(|p| {
            p.is_file()
                && p.extension().is_some_and(|e| ["glsl", "comp", "rgen", "rchit", "rmiss"].iter().any(|x| e == *x))
        })
        .collect();
    files.sort();
    let mut s = String::from("&[\n");
    for p in &files {
        let name = p.file_name().expect("a file name").to_string_lossy();
        s += &format!("    ({name:?}, include_str!({:?})),\n", p.display().to_string());
    }
    s += "]\n";
    let out = std::path::Path::new(&std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("glsl_sources.rs");
    std::fs::write(out, s).expect("writing glsl_sources.rs");
    println!("cargo:rerun-if-changed=glsl");
}
