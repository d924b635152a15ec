//! `halftrace isa`: the compiler's view of each kernel on RADV null devices or a device with
//! pipeline statistics; writes isa.md, isa.csv, isa.json and the plots.

use super::outln;
use crate::cli::IsaArgs;
use crate::isa::{self, Matrix, Target};
use crate::outdir::OutDir;
use crate::report::isa::IsaRow;
use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;

/// The files `isa` writes into its folder (`--force` replaces them, nothing else).
const OUTPUTS: &[&str] =
    &["isa.md", "isa.csv", "isa.json", "isa_vgprs.png", "isa_vgprs.svg", "isa_scratch.png", "isa_scratch.svg"];

fn line(r: &IsaRow) -> String {
    let f = |x: Option<f64>| x.map(|v| format!("{v:.0}")).unwrap_or_else(|| "–".into());
    if !r.status.is_ok() {
        return format!("{:<10} {:<34} {}", r.family, r.kernel, r.status);
    }
    let packed =
        r.asm.map(|a| format!("fp16 VALU packed {}/{}", a.packed_f16, a.packed_f16 + a.scalar_f16)).unwrap_or_default();
    format!(
        "{:<10} {:<34} VGPRs {}, scratch {} KiB/wave, waves/SIMD {}, instructions {}, {packed}",
        if r.family.is_empty() { &r.device } else { &r.family },
        r.kernel,
        f(r.vgprs),
        r.scratch_bytes.map(|b| format!("{:.1}", b / 1024.0)).unwrap_or_else(|| "–".into()),
        f(r.waves_per_simd),
        f(r.instructions)
    )
}

pub fn isa(a: &IsaArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    // The folder first: a bad one is refused before any null device is probed.
    let out = a.out.clone().unwrap_or_else(|| {
        let d = crate::sweep::default_out();
        let name = d.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
        d.with_file_name(format!("isa-{name}"))
    });
    let _lock = OutDir::claim(&out, "--out")?;
    let held: Vec<&str> = OUTPUTS.iter().chain(&["disasm"]).copied().filter(|f| out.join(f).exists()).collect();
    anyhow::ensure!(
        held.is_empty() || a.force,
        "{} already holds {} from an earlier isa run; name another --out, or --force to replace them",
        out.display(),
        held.join(", ")
    );
    let mut targets: Vec<Target> = Vec::new();
    let exe = std::env::current_exe()?;
    let wants_families = !a.family.is_empty() || a.device.is_empty();
    let known = if wants_families { isa::known_families(&exe) } else { Vec::new() };
    let families: Vec<String> = if a.family.iter().any(|f| f.eq_ignore_ascii_case("all")) {
        known.iter().map(|f| f.name.to_string()).collect()
    } else if a.family.is_empty() && a.device.is_empty() {
        isa::default_families(&known)
    } else {
        a.family.iter().map(|f| f.to_lowercase()).collect()
    };
    let names: Vec<&str> = known.iter().map(|f| f.name).collect();
    anyhow::ensure!(
        !wants_families || !names.is_empty(),
        "no RADV null device opens here (RADV, in Debian's mesa-vulkan-drivers, provides them for any AMD family); \
         or name a device whose driver reports pipeline statistics with --device"
    );
    for f in families {
        anyhow::ensure!(
            names.contains(&f.as_str()),
            "--family '{f}': the installed RADV opens no null device for it (it does for: {})",
            names.join(", ")
        );
        targets.push(Target::Family(f));
    }
    targets.extend(a.device.iter().cloned().map(Target::Device));
    // Each device once: a repeated name would give rows `report` refuses as duplicates.
    let mut seen = Vec::new();
    targets.retain(|t| {
        if seen.contains(t) {
            false
        } else {
            seen.push(t.clone());
            true
        }
    });
    let matrix = match (a.quick, a.full) {
        (true, _) => Matrix::Quick,
        (_, true) => Matrix::Full,
        _ => Matrix::Default,
    };
    // The representations go to a folder of their own first, which replaces disasm/ only once
    // the run has succeeded (a failed run leaves the earlier one as it was).
    let disasm: Option<PathBuf> = a.disasm.then(|| out.join(format!(".disasm-{}.tmp", std::process::id())));
    let cfg = isa::Config { targets, builds: isa::plan(matrix, &a.layouts), disasm, validation: a.validation };
    let quiet = a.quiet;
    let mut stdout_err = None;
    let result = isa::run(&cfg, |r| {
        if !quiet && stdout_err.is_none() {
            use std::io::Write as _;
            if let Err(e) = writeln!(std::io::stdout(), "{}", line(r)) {
                stdout_err = Some(e);
            }
        }
    });
    let s = match (result, stdout_err) {
        (Ok(s), None) => s,
        (r, e) => {
            if let Some(d) = &cfg.disasm {
                let _ = std::fs::remove_dir_all(d);
            }
            return Err(r.err().unwrap_or_else(|| e.map(anyhow::Error::from).expect("one of the two failed")));
        }
    };
    crate::report::isa::write(&out, &s.rows)?;
    crate::report::isa::render(&s.rows, &out)?;
    if let Some(tmp) = &cfg.disasm {
        let dest = out.join("disasm");
        if dest.exists() {
            std::fs::remove_dir_all(&dest).with_context(|| format!("replacing {}", dest.display()))?;
        }
        if tmp.exists() {
            std::fs::rename(tmp, &dest).with_context(|| format!("moving the representations to {}", dest.display()))?;
        }
    }
    let skipped = s.rows.iter().filter(|r| r.status.is_skipped()).count();
    let failed: Vec<&str> = s.rows.iter().filter(|r| r.status.is_failed()).map(|r| r.kernel.as_str()).collect();
    outln!(
        "{} kernel builds ({} ok, {skipped} skipped, {} failed) on {} device(s) in {:.1} s; report: {}",
        s.rows.len(),
        s.rows.len() - skipped - failed.len(),
        failed.len(),
        cfg.targets.len(),
        t0.elapsed().as_secs_f64(),
        out.join("isa.md").display()
    );
    if a.validation {
        anyhow::ensure!(
            s.validation_messages.is_empty(),
            "{} validation-layer message(s), the first: {}",
            s.validation_messages.len(),
            s.validation_messages[0]
        );
    }
    anyhow::ensure!(failed.is_empty(), "{} kernel(s) did not build: {}", failed.len(), failed.join(", "));
    Ok(())
}

/// `halftrace probe-family` (hidden): the null devices RADV lists with `RADV_FORCE_FAMILY` as
/// this process was given it.
pub fn probe_family() -> anyhow::Result<()> {
    for name in crate::gpu::null::listed()? {
        outln!("{name}");
    }
    Ok(())
}
