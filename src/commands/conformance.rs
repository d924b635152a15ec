//! `halftrace conformance`: every variant against its CPU reference on one device.

use super::outln;
use crate::argv::Argv;
use crate::conformance;
use crate::outdir::{OutDir, OutMode, Outputs};
use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct ConformanceArgs {
    /// A covering subset (each layout, B, P, math, float-control mode and packet
    /// implementation at least once) instead of the full cross product.
    #[arg(long)]
    pub quick: bool,
    /// Scene file (repeat for several; default: the bundled scene).
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Also every .obj / .obj.gz scene in this folder.
    #[arg(long)]
    pub scenes_dir: Option<PathBuf>,
    /// Vulkan device: index or name substring (see `halftrace devices`).
    #[arg(long)]
    pub device: Option<String>,
    /// Output folder for conformance.md and conformance.csv (default
    /// reports/conformance-<UTC timestamp>/). Its conformance files, if any, are refused
    /// unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace the conformance files in --out.
    #[arg(long)]
    pub force: bool,
    /// Run under the Khronos validation layer; any message fails the run.
    #[arg(long)]
    pub validation: bool,
    /// Treat a device feature as missing (testing the fallbacks).
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
}

impl ConformanceArgs {
    /// This command's line, every argument as set.
    pub fn argv(&self) -> Argv {
        Argv::new("conformance")
            .flag("quick", self.quick)
            .each("scene", self.scene.iter().map(|p| p.display()))
            .opt("scenes-dir", self.scenes_dir.as_ref().map(|p| p.display()))
            .opt("device", self.device.as_ref())
            .opt("out", self.out.as_ref().map(|p| p.display()))
            .flag("force", self.force)
            .flag("validation", self.validation)
            .each("mask-feature", &self.mask_feature)
    }
}

/// What `conformance` writes into its folder, which it may share: these files, refused unless
/// `--force`, which replaces them (each as it is written, at the end), nothing else.
const OUTPUTS: Outputs = Outputs {
    command: "conformance",
    owns: |n| n == "conformance.csv" || n == "conformance.md",
    folders: &[],
    alone: false,
    resume: None,
    force: true,
};

pub fn conformance(a: &ConformanceArgs) -> anyhow::Result<()> {
    // The folder first: a bad one is refused before the run, not after it.
    let out = a.out.clone().unwrap_or_else(|| crate::outdir::default_out(Some("conformance")));
    let _out = OutDir::claim_for(&out, "--out", OutMode::from_flags(false, a.force)?, &OUTPUTS)?;
    let mut scenes = a.scene.clone();
    if let Some(d) = &a.scenes_dir {
        let found = crate::scene::obj_files_in(d).with_context(|| format!("--scenes-dir {}", d.display()))?;
        anyhow::ensure!(!found.is_empty(), "--scenes-dir {}: no .obj or .obj.gz scenes in it", d.display());
        scenes.extend(found);
    }
    if scenes.is_empty() {
        scenes.push(PathBuf::from(crate::sweep::DEFAULT_SCENE));
    }
    let opts = conformance::Options {
        quick: a.quick,
        scenes,
        device: a.device.clone(),
        mask_features: a.mask_feature.clone(),
        validation: a.validation,
    };
    let o = conformance::run(&opts, |line| eprintln!("{line}"))?;
    conformance::write(&o, a.quick, &out)?;
    outln!("{}", conformance::markdown(&o, a.quick));
    let md = out.join("conformance.md");
    outln!("written to {}", md.display());
    anyhow::ensure!(
        o.validation.is_empty(),
        "{} validation layer message(s); see {}",
        o.validation.len(),
        md.display()
    );
    let fails: Vec<String> = o.failures().iter().map(|c| c.variant.kernel_name(c.imp, false)).collect();
    anyhow::ensure!(fails.is_empty(), "{} kernel(s) failed conformance: {}", fails.len(), fails.join(", "));
    Ok(())
}
