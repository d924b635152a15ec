//! `halftrace bench`: the speed ratios a kernel change is judged by.

use super::outln;
use super::LayoutArg;
use crate::argv::Argv;
use crate::bench::{self, BenchConfig};
use crate::rays::RayKind;
use anyhow::Context as _;
use std::path::PathBuf;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct BenchArgs {
    /// Scenes (OBJ, glTF or PLY); repeat the flag. Default: the bundled teapot, and
    /// sponza_dabrovic (a large interior) and igea (a 270k-triangle scan) from the test scenes
    /// (`tests/scenes`, else `../shared/scenes`) when they are there.
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Ray kinds, comma-separated: primary, ao, diffuse, grazing.
    #[arg(long, default_value = "primary,ao,diffuse", value_delimiter = ',')]
    pub rays: Vec<crate::rays::RayKind>,
    /// Reduced-precision layouts to time beside f32, comma-separated (default: every
    /// conservative one) — for a quicker check of one layout's change.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<LayoutArg>,
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    #[arg(long, default_value_t = 256)]
    pub height: u32,
    /// Branching factors of the P = 1 kernels, comma-separated: 2, 4, 8, 16 (the fixed ratios
    /// are at B = 8; f16h ÷ f32 is reported at each other one).
    #[arg(long, default_value = "4,8", value_delimiter = ',')]
    pub branchings: Vec<usize>,
    /// Interleaved rounds (every target once per round).
    #[arg(long, default_value_t = 5)]
    pub rounds: usize,
    /// Timed dispatches per target and round (after one warm-up).
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Vulkan device (index or name substring).
    #[arg(long)]
    pub device: Option<String>,
    /// Enable the Khronos validation layer.
    #[arg(long)]
    pub validation: bool,
    /// Also write the report (Markdown) to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl BenchArgs {
    /// This command's line, every argument as set.
    pub fn argv(&self) -> Argv {
        Argv::new("bench")
            .each("scene", self.scene.iter().map(|p| p.display()))
            .list("rays", &self.rays)
            .list("layouts", &self.layouts)
            .opt("width", Some(self.width))
            .opt("height", Some(self.height))
            .list("branchings", &self.branchings)
            .opt("rounds", Some(self.rounds))
            .opt("repeat", Some(self.repeat))
            .opt("device", self.device.as_ref())
            .flag("validation", self.validation)
            .opt("out", self.out.as_ref().map(|p| p.display()))
    }
}

pub fn bench(a: &BenchArgs) -> anyhow::Result<()> {
    let mut scenes = a.scene.clone();
    if scenes.is_empty() {
        scenes.push(PathBuf::from(crate::sweep::DEFAULT_SCENE));
        if let Some(d) = crate::scene::default_scenes_dir() {
            for s in ["sponza_dabrovic.obj", "sponza_dabrovic.obj.gz", "igea.obj.gz"] {
                if d.join(s).is_file() {
                    scenes.push(d.join(s));
                }
            }
        }
    }
    for k in &a.rays {
        anyhow::ensure!(
            !matches!(k, RayKind::File(_)),
            "--rays {k}: bench uses the generated kinds (primary, ao, diffuse, grazing)"
        );
    }
    crate::rays::check_image_size(a.width, a.height).map_err(anyhow::Error::msg)?;
    if let Some(o) = &a.out {
        crate::fsx::check_output("--out", o)?;
        anyhow::ensure!(
            !o.exists(),
            "--out {} exists; a report is never overwritten (remove it or name another file)",
            o.display()
        );
        // Written at the end of the run: a folder that is not there would fail it only then.
        let dir = o.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
        anyhow::ensure!(dir.is_dir(), "--out {}: {} is not a folder", o.display(), dir.display());
    }
    // Each scene once: its rows would be timed twice under one name.
    crate::sweep::check_scenes("--scene", &scenes)?;
    anyhow::ensure!(!a.branchings.is_empty(), "--branchings: name at least one of 2, 4, 8, 16");
    for &b in &a.branchings {
        crate::bvh::check_branching(b).context("--branchings")?;
    }
    let mut layouts = Vec::new();
    for l in &a.layouts {
        match l {
            LayoutArg::Layout(id) => layouts.push(*id),
            LayoutArg::Baseline(b) => {
                anyhow::bail!("--layouts {b}: a baseline; rq, rt and embree are always timed when the device has them")
            }
        }
    }
    let cfg = BenchConfig {
        scenes,
        kinds: a.rays.clone(),
        width: a.width,
        height: a.height,
        rounds: a.rounds,
        repeat: a.repeat,
        device: a.device.clone(),
        validation: a.validation,
        layouts,
        branchings: a.branchings.clone(),
    };
    let r = bench::run(&cfg)?;
    let md = bench::markdown(&cfg, &r);
    outln!("{md}");
    if let Some(o) = &a.out {
        crate::fsx::write_atomic(o, md.as_bytes())?;
        outln!("report written to {}", o.display());
    }
    Ok(())
}
