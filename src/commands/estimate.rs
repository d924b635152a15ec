//! `halftrace estimate`: ACO's cycle estimate of each kernel taken apart per loop, on RADV
//! null devices, and weighted by the work of real rays; writes estimate.md, estimate.csv and
//! estimate-rays.csv.

use super::outln;
use crate::estimate;
use crate::isa::{self, Matrix};
use crate::outdir::{OutDir, OutMode, Outputs};
use anyhow::Context as _;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct EstimateArgs {
    /// AMD families, comma-separated (RADV null devices: e.g. navi31, navi21, navi10, vega10,
    /// gfx1201), and other vendors' models (a740, g610, lnl, ga102, v3d-71: their compilers'
    /// whole-shader estimates, shown beside); `vendors`: every model, `all`: every family the
    /// installed RADV opens and every model (as `isa` takes them).
    #[arg(long, value_delimiter = ',', default_value = "navi31")]
    pub family: Vec<String>,
    /// Kernels: layouts (every layout and math at B = 4), cover, default, full or singles (every
    /// layout and math at every B, P = 1).
    #[arg(long, default_value = "default")]
    pub matrix: String,
    /// Only these layouts (and f32, the reference).
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Scenes whose rays weight the loops (OBJ, glTF or PLY; repeatable).
    #[arg(long, default_value = "scenes/teapot.obj")]
    pub scene: Vec<std::path::PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing or a .npy file).
    #[arg(long, value_delimiter = ',', default_value = "primary,ao")]
    pub rays: Vec<String>,
    /// Image side of the primary rays (ao and diffuse start from their hits).
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// Output folder (default reports/estimate-<UTC timestamp>/). Its estimate files, if any,
    /// are refused unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Replace the estimate files in --out.
    #[arg(long)]
    pub force: bool,
    /// The compilers release: `newest` (Debian's newest Mesa, scripts/install-newest-compilers.sh:
    /// AMD's families under its amdgpu shim) or a compilers folder; default: the pinned build of
    /// scripts/install-compilers.sh for the other vendors, the installed RADV's null devices for
    /// AMD. Each row's driver names its Mesa release.
    #[arg(long)]
    pub compilers: Option<String>,
}

const FILES: &[&str] =
    &["estimate.md", "estimate.csv", "estimate-rays.csv", "estimate-rays.json", "estimate.png", "estimate.svg"];

/// Like `isa`'s, the folder may be a sweep's or an isa run's: only its own files are refused.
const OUTPUTS: Outputs = Outputs {
    command: "estimate",
    owns: |n| FILES.contains(&n),
    folders: &[],
    alone: false,
    resume: None,
    force: true,
};

pub fn estimate(a: &EstimateArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let matrix = Matrix::parse(&a.matrix)
        .ok_or_else(|| anyhow::anyhow!("--matrix {}: layouts, cover, default, full or singles", a.matrix))?;
    let out = a.out.clone().unwrap_or_else(|| crate::outdir::default_out(Some("estimate")));
    let _out = OutDir::claim_for(&out, "--out", OutMode::from_flags(false, a.force)?, &OUTPUTS)?;
    let exe = std::env::current_exe()?;
    // As `isa` takes them (`vendors` is every other vendor's model, `all` every AMD family and
    // every model), on one release: with one whose folder has the amdgpu shim (Mesa 26 on),
    // AMD's families are built under it.
    let mut families: Vec<String> = Vec::new();
    let (mut amd, mut compilers, mut models): (Option<PathBuf>, Option<PathBuf>, Vec<String>) =
        (None, None, Vec::new());
    for t in isa::release_targets(&a.family, &exe, false, a.compilers.as_deref(), false)? {
        match t {
            isa::Target::Family(f, dir) => {
                families.push(f);
                amd = dir;
            }
            isa::Target::Model(m, dir) => {
                models.push(m);
                compilers = Some(dir);
            }
            isa::Target::Device(_) => {}
        }
    }
    let kinds: Vec<crate::rays::RayKind> = a
        .rays
        .iter()
        .map(|k| k.parse().map_err(|e| anyhow::anyhow!("--rays {k}: {e}")))
        .collect::<anyhow::Result<_>>()?;
    anyhow::ensure!(a.res > 0, "--res must be at least 1");
    // Scenes load after the kernels are built: a missing one is refused before.
    for (i, scene) in a.scene.iter().enumerate() {
        anyhow::ensure!(scene.exists(), "--scene {}: no such file", scene.display());
        if let Some(first) = a.scene[..i].iter().find(|s| crate::fsx::same_file(s, scene)) {
            anyhow::bail!(
                "--scene {} is the same file as --scene {}: its rows would count twice",
                scene.display(),
                first.display()
            );
        }
        // Every scene loads before any kernel is built (building takes minutes on five families).
        crate::scene::load(scene).with_context(|| format!("--scene {}", scene.display()))?;
    }
    let rays = estimate::Rays { scenes: a.scene.clone(), kinds, res: a.res };
    let (rows, ray_rows) = estimate::run(&exe, &families, matrix, &a.layouts, &rays, amd.as_deref())?;
    // The other vendors: their compilers' whole-shader estimates, beside.
    let vendor_rows = if models.is_empty() {
        Vec::new()
    } else {
        let dir = compilers.clone().expect("models have a compilers folder");
        let cfg = isa::Config {
            targets: models.iter().map(|m| isa::Target::Model(m.clone(), dir.clone())).collect(),
            matrix,
            layouts: a.layouts.clone(),
            branchings: Vec::new(),
            disasm: None,
            validation: false,
            releases: 1,
        };
        isa::run(&cfg, &exe, |_| {})?.rows
    };
    estimate::write(&out, &rows, &ray_rows, &vendor_rows)?;
    let failed: Vec<String> = rows
        .iter()
        .map(|r| &r.status)
        .chain(ray_rows.iter().map(|r| &r.status))
        .chain(vendor_rows.iter().map(|r| &r.status))
        .filter(|s| s.is_failed())
        .map(|s| s.to_string())
        .collect();
    outln!(
        "{} kernels on {} famil{} taken apart ({} rebuilt exactly), {} estimated on {} ray set(s) in {:.1} s; report: {}",
        rows.len(),
        families.len(),
        if families.len() == 1 { "y" } else { "ies" },
        rows.iter().filter(|r| r.status.is_ok()).count(),
        ray_rows.iter().filter(|r| r.status.is_ok()).count(),
        rays.sets(),
        t0.elapsed().as_secs_f64(),
        out.join("estimate.md").display()
    );
    anyhow::ensure!(failed.is_empty(), "{} kernel(s) failed:\n{}", failed.len(), failed.join("\n"));
    Ok(())
}
