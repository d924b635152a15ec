//! `halftrace isa`: the compiler's view of each kernel on RADV null devices or a device with
//! pipeline statistics; writes isa.md, isa.csv, isa.json and the plots.

use super::outln;
use crate::argv::Argv;
use crate::isa::{self, Matrix, Target};
use crate::outdir::{OutDir, OutMode, Outputs};
use crate::report::isa::IsaRow;
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The representations of a run that succeeded (`tmp`) in place of an earlier run's (`dest`).
fn replace_disasm(tmp: &Path, dest: &Path) -> anyhow::Result<()> {
    if dest.exists() {
        std::fs::remove_dir_all(dest).with_context(|| format!("replacing {}", dest.display()))?;
    }
    if tmp.exists() {
        std::fs::rename(tmp, dest).with_context(|| format!("moving the representations to {}", dest.display()))?;
    }
    Ok(())
}

/// `isa-model`'s arguments: `isa` builds them ([`isa::ModelArgs`]).
pub use crate::isa::ModelArgs as IsaModelArgs;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct IsaArgs {
    /// GPU families and models, comma-separated. AMD through RADV's null devices (e.g.
    /// navi31,navi21,vega10); other vendors through Mesa's drm-shims, once
    /// scripts/install-compilers.sh has built them: a618,a660,a740,a750 (Qualcomm Adreno),
    /// g52,g610 (Arm Mali), tgl,dg2,mtl,lnl,bmg (Intel), tu102,ga102 (NVIDIA),
    /// v3d-42,v3d-71 (Broadcom). `vendors`: every model of the other vendors; `all`: every AMD
    /// family the installed RADV knows and every model. Default, without --device: polaris10,
    /// vega10, navi10, navi21, navi31, gfx1201 (GCN4 to RDNA4).
    #[arg(long, value_delimiter = ',')]
    pub family: Vec<String>,
    /// A Vulkan device (index or name substring) whose driver exposes
    /// VK_KHR_pipeline_executable_properties; repeat for several.
    #[arg(long)]
    pub device: Vec<String>,
    /// Layouts beside f32, comma-separated (default: every layout).
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Every layout and math at B = 4, P = 1 only.
    #[arg(long, conflicts_with = "full")]
    pub quick: bool,
    /// Every layout, math, B and P, every packet implementation, float controls on and off.
    #[arg(long)]
    pub full: bool,
    /// Output folder (default reports/isa-<UTC timestamp>/). Its isa.* files, if any, are
    /// refused unless --force; other files there are left alone (a sweep folder may hold both).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the isa files in --out.
    #[arg(long)]
    pub force: bool,
    /// Also write each kernel's internal representations (NIR, ACO IR, disassembly) under
    /// disasm/<family>/.
    #[arg(long)]
    pub disasm: bool,
    /// Run under the Khronos validation layer; any message fails the run.
    #[arg(long)]
    pub validation: bool,
    /// No line per kernel.
    #[arg(long)]
    pub quiet: bool,
    /// The compilers release(s), comma-separated: `pinned` (the default: the other vendors
    /// from scripts/install-compilers.sh's build, AMD from the installed RADV's null devices),
    /// `newest` (Debian's newest Mesa, scripts/install-newest-compilers.sh: AMD under its amdgpu
    /// shim) or a compilers folder. Two or more build everything asked on each, side by side,
    /// and isa.md shows what the release changes. Each row's driver names its Mesa release.
    #[arg(long, value_delimiter = ',')]
    pub compilers: Vec<String>,
}

impl IsaArgs {
    /// This command's line, every argument as set.
    pub fn argv(&self) -> Argv {
        Argv::new("isa")
            .list("family", &self.family)
            .each("device", &self.device)
            .list("layouts", &self.layouts)
            .flag("quick", self.quick)
            .flag("full", self.full)
            .opt("out", self.out.as_ref().map(|p| p.display()))
            .flag("force", self.force)
            .flag("disasm", self.disasm)
            .flag("validation", self.validation)
            .flag("quiet", self.quiet)
            .list("compilers", &self.compilers)
    }
}

/// The files (and the folder) `isa` writes into its output folder.
const FILES: &[&str] = &[
    "isa.md",
    "isa.csv",
    "isa.json",
    "isa_vgprs.png",
    "isa_vgprs.svg",
    "isa_scratch.png",
    "isa_scratch.svg",
    "disasm",
];

/// `isa`'s folder may be a sweep's: only its own [`FILES`] are refused unless `--force`, which
/// replaces them (each as it is written, once every kernel is built) and nothing else.
const OUTPUTS: Outputs = Outputs {
    command: "isa",
    owns: |n| FILES.contains(&n),
    folders: &["disasm"],
    alone: false,
    resume: None,
    force: true,
};

fn line(r: &IsaRow) -> String {
    let f = |x: Option<f64>| x.map(|v| format!("{v:.0}")).unwrap_or_else(|| "–".into());
    if !r.status.is_ok() {
        return format!("{:<10} {:<34} {}", r.family, r.kernel, r.status);
    }
    let packed = r
        .asm
        .filter(|a| a.packed_f16 + a.scalar_f16 > 0)
        .map(|a| format!(", fp16 ALU packed {}/{}", a.packed_f16, a.packed_f16 + a.scalar_f16))
        .unwrap_or_default();
    format!(
        "{:<10} {:<34} registers {}, private {} B, spills {}, {} {}, instructions {}, cycles {}{packed}",
        if r.family.is_empty() { &r.device } else { &r.family },
        r.kernel,
        f(r.registers),
        f(r.private_bytes),
        f(r.spills),
        f(r.occupancy),
        if r.occupancy_unit.is_empty() { "occupancy" } else { &r.occupancy_unit },
        f(r.instructions),
        f(r.cycles)
    )
}

pub fn isa(a: &IsaArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    // The folder first: a bad one is refused before any null device is probed.
    let out = a.out.clone().unwrap_or_else(|| crate::outdir::default_out(Some("isa")));
    let _out = OutDir::claim_for(&out, "--out", OutMode::from_flags(false, a.force)?, &OUTPUTS)?;
    let exe = std::env::current_exe()?;
    let (mut targets, releases) = isa::releases_targets(&a.family, &exe, a.device.is_empty(), &a.compilers)?;
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
        (true, _) => Matrix::Layouts,
        (_, true) => Matrix::Full,
        _ => Matrix::Default,
    };
    // The representations go to a folder of their own first, which replaces disasm/ only once
    // the run has succeeded (a failed run leaves the earlier one as it was).
    let disasm: Option<PathBuf> = a.disasm.then(|| out.join(format!(".disasm-{}.tmp", std::process::id())));
    let cfg = isa::Config {
        targets,
        matrix,
        layouts: a.layouts.clone(),
        branchings: Vec::new(),
        disasm,
        validation: a.validation,
        releases,
    };
    let quiet = a.quiet;
    let mut stdout_err = None;
    let result = isa::run(&cfg, &exe, |r| {
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
        replace_disasm(tmp, &out.join("disasm"))?;
    }
    for n in &s.notes {
        eprintln!("warning: {n}");
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

/// `halftrace isa-model` (hidden): the isa matrix on the model whose drm-shim environment this
/// process has, one JSON row per line on stdout (read by `isa`, `isa::shim::run_model`).
pub fn isa_model(a: &IsaModelArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        crate::vendor::find_model(&a.model).is_some() || crate::gpu::null::family(&a.model).is_some(),
        "--model {}: no such model or AMD family",
        a.model
    );
    let matrix = Matrix::parse(&a.matrix)
        .ok_or_else(|| anyhow::anyhow!("--matrix {}: layouts, cover, default, full or singles", a.matrix))?;
    let mut builds = isa::plan_at(matrix, &a.layouts, &a.branchings);
    if a.marked {
        for b in &mut builds {
            b.source = crate::variant::Source::Marked;
        }
    }
    let messages = isa::run_model_here(&a.model, &builds, a.validation, a.disasm.as_deref())?;
    anyhow::ensure!(
        messages.is_empty(),
        "{} validation-layer message(s), the first: {}",
        messages.len(),
        messages.first().map(String::as_str).unwrap_or("")
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    /// The model child's command line parses back, with clap, into the arguments it was built
    /// from.
    #[test]
    fn the_model_childs_command_parses_back() {
        let a = crate::isa::ModelArgs {
            model: "a740".into(),
            matrix: "layouts".into(),
            layouts: vec!["f16h".parse().unwrap(), "q8".parse().unwrap()],
            branchings: vec![4, 8],
            validation: true,
            disasm: Some("out dir/-x".into()),
            marked: true,
        };
        let argv = std::iter::once("halftrace".to_string()).chain(a.argv().0);
        let got = crate::commands::Cli::try_parse_from(argv).unwrap();
        assert_eq!(got.cmd, crate::commands::Cmd::IsaModel(a));
    }
}
