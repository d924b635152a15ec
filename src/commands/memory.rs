//! `halftrace memory`: bytes and cache lines per ray from the CPU reference's exact walk, and a
//! cache model of each GPU; writes memory.md, memory.csv and memory.json.

use super::outln;
use crate::memory::{self, gpus};
use crate::outdir::{OutDir, OutMode, Outputs};
use anyhow::Context as _;
use std::time::Instant;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct MemoryArgs {
    /// GPU models, comma-separated (navi31, navi21, vega10, g610, a740, lnl, ga102, h100, h200;
    /// default: all).
    #[arg(long, value_delimiter = ',')]
    pub gpu: Vec<String>,
    /// Only these layouts (and f32, the reference); every math of each.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<crate::layout::LayoutId>,
    /// Branching factors, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "4,8")]
    pub branchings: Vec<usize>,
    /// Packet sizes, comma-separated (1: single rays; a packet's P rays share one traversal,
    /// lanes of one wave; its stack is in shared memory or registers and moves no memory
    /// traffic in the model).
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub packets: Vec<usize>,
    /// Scenes (OBJ, glTF or PLY; repeatable).
    #[arg(long, default_value = "scenes/teapot.obj")]
    pub scene: Vec<std::path::PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing or a .npy file).
    #[arg(long, value_delimiter = ',', default_value = "primary,ao,diffuse")]
    pub rays: Vec<String>,
    /// Image side of the primary rays (ao and diffuse start from their hits).
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// A folder of `halftrace estimate` (its estimate-rays.json): the issue cycles of the AMD
    /// families it estimated bound their rays/s beside DRAM's (the roofline).
    #[arg(long)]
    pub estimate: Option<std::path::PathBuf>,
    /// The compilers release whose occupancy sets each kernel's resident waves per unit in the
    /// cache model: `pinned`, `newest` or a compilers folder (as `isa --compilers`). Every
    /// single-ray kernel is built first on the compilers of navi31, navi21, vega10 (RADV), a740
    /// (turnip), g610 (panfrost: its thread class) and ga102 (NVK; h100 and h200 take its
    /// registers with Hopper's warp limit), those asked and that release has; lnl keeps its
    /// assumed figure.
    /// Default: every model's assumed figure.
    #[arg(long)]
    pub compilers: Option<String>,
    /// Leave the traversal stacks out of the lines and the cache model (by default a single
    /// ray's stack is in private memory, as every modelled GPU's compiler keeps it).
    #[arg(long)]
    pub no_stack: bool,
    /// What-if: every layout's nodes padded to a multiple of this many bytes (e.g. 64: q8's 56-byte
    /// node in one 64-byte line) — no kernel places them so; the model says what it would save.
    #[arg(long, default_value_t = 0)]
    pub node_align: u64,
    /// What-if: every layout's nodes re-indexed in this order — `bfs` (each node's inner
    /// children side by side, level by level), `dfs` (each subtree contiguous, children in slot
    /// order) — instead of as the layouts store them (`layout`: breadth first, every layout).
    /// Hits and requested bytes are the same; lines and caches differ.
    #[arg(long, value_enum, default_value_t = memory::NodeOrder::Layout)]
    pub node_order: memory::NodeOrder,
    /// Output folder (default reports/memory-<UTC timestamp>/). Its memory files, if any, are
    /// refused unless --force; other files there are left alone.
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Replace the memory files in --out.
    #[arg(long)]
    pub force: bool,
}

const FILES: &[&str] = &["memory.md", "memory.csv", "memory.json"];

/// Like `estimate`'s, the folder may be another command's: only its own files are refused.
const OUTPUTS: Outputs =
    Outputs { command: "memory", owns: |n| FILES.contains(&n), folders: &[], alone: false, resume: None, force: true };

pub fn memory(a: &MemoryArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let gpus: Vec<&'static gpus::Gpu> = if a.gpu.is_empty() {
        gpus::GPUS.iter().collect()
    } else {
        a.gpu
            .iter()
            .map(|g| {
                gpus::gpu(&g.to_lowercase()).ok_or_else(|| {
                    anyhow::anyhow!(
                        "--gpu '{g}': not a modelled GPU (use {})",
                        gpus::GPUS.iter().map(|g| g.id).collect::<Vec<_>>().join(", ")
                    )
                })
            })
            .collect::<anyhow::Result<_>>()?
    };
    for &b in &a.branchings {
        crate::bvh::check_branching(b).map_err(|e| anyhow::anyhow!("--branchings: {e}"))?;
    }
    for &p in &a.packets {
        anyhow::ensure!(
            crate::variant::PACKETS.contains(&p),
            "--packets {p}: a packet size is one of {}",
            crate::variant::PACKETS.map(|p| p.to_string()).join(", ")
        );
    }
    let kinds: Vec<crate::rays::RayKind> = a
        .rays
        .iter()
        .map(|k| k.parse().map_err(|e| anyhow::anyhow!("--rays {k}: {e}")))
        .collect::<anyhow::Result<_>>()?;
    anyhow::ensure!(a.res > 0, "--res must be at least 1");
    anyhow::ensure!(
        a.node_align == 0 || (a.node_align.is_power_of_two() && (4..=4096).contains(&a.node_align)),
        "--node-align {}: 0 (nodes as the layouts pack them) or a power of two from 4 to 4096 bytes",
        a.node_align
    );
    for scene in &a.scene {
        anyhow::ensure!(scene.exists(), "--scene {}: no such file", scene.display());
    }
    let out = a.out.clone().unwrap_or_else(|| crate::outdir::default_out(Some("memory")));
    let _out = OutDir::claim_for(&out, "--out", OutMode::from_flags(false, a.force)?, &OUTPUTS)?;
    let estimates = match &a.estimate {
        None => Vec::new(),
        Some(d) => crate::report::estimate::read(d)?
            .ok_or_else(|| anyhow::anyhow!("--estimate {}: no estimate-rays.json there", d.display()))?,
    };
    let isa_rows = match &a.compilers {
        None => Vec::new(),
        Some(c) => {
            // Every scene loads before the kernels are built (a minute on five models).
            for scene in &a.scene {
                crate::scene::load(scene).with_context(|| format!("--scene {}", scene.display()))?;
            }
            let rows = occupancy(&gpus, &a.layouts, &a.branchings, c)?;
            check_estimate_release(&rows, &estimates, a.estimate.as_deref())?;
            rows
        }
    };
    let cfg = memory::Config {
        scenes: a.scene.clone(),
        kinds,
        res: a.res,
        gpus: gpus.clone(),
        variants: memory::default_variants(&a.branchings, &a.packets, &a.layouts),
        estimates,
        stack: !a.no_stack,
        node_align: a.node_align,
        node_order: a.node_order,
        isa_rows,
    };
    let rows = memory::run(&cfg, |_| {})?;
    // Each GPU's release: its own compiler's (AMD's may be another build than the others').
    let release = |g: &gpus::Gpu| {
        let t = g.compiler?;
        cfg.isa_rows.iter().find(|r| r.family == t).map(|r| crate::report::isa::release(&r.driver))
    };
    let mut gpus_table = gpus::table(&gpus, release);
    if a.node_align > 0 {
        gpus_table += &format!(
            "**What-if (`--node-align {}`)**: every layout's nodes padded to a multiple of {} bytes; no kernel \
             places them so. Requested node bytes stay the records'; lines and the cache model see the padding.\n\n",
            a.node_align, a.node_align
        );
    }
    if a.node_order != memory::NodeOrder::Layout {
        gpus_table += &format!(
            "**What-if (`--node-order {}`)**: every layout's nodes re-indexed {}; no kernel places them so. \
             Requested bytes stay; lines and the cache model see the new places.\n\n",
            a.node_order.name(),
            a.node_order.what()
        );
    }
    let md = crate::report::memory::markdown(&rows, &gpus_table);
    crate::fsx::write_atomic(&out.join("memory.csv"), &crate::report::memory::csv(&rows)?)?;
    crate::fsx::write_atomic(&out.join("memory.json"), serde_json::to_string_pretty(&rows)?.as_bytes())?;
    crate::fsx::write_atomic(&out.join("memory.md"), md.as_bytes())?;
    for v in crate::report::memory::verdicts(&rows) {
        outln!("{v}");
    }
    outln!(
        "{} rows in {:.1} s; written to {}",
        rows.len(),
        t0.elapsed().as_secs_f64(),
        out.join("memory.md").display()
    );
    Ok(())
}

/// `isa`'s rows of every single-ray kernel (of `layouts` and f32, at `branchings`) on the
/// compilers of the GPU models in `gpus` that have one ([`gpus::Gpu::compiler`]), on release
/// `compilers`.
fn occupancy(
    gpus: &[&gpus::Gpu],
    layouts: &[crate::layout::LayoutId],
    branchings: &[usize],
    compilers: &str,
) -> anyhow::Result<Vec<crate::report::isa::IsaRow>> {
    use crate::isa;
    // Each compiler once (Hopper borrows GA102's), in the order the GPUs were asked.
    let mut names: Vec<String> = Vec::new();
    for n in gpus.iter().filter_map(|g| g.compiler) {
        if !names.iter().any(|m| m == n) {
            names.push(n.to_string());
        }
    }
    anyhow::ensure!(
        !names.is_empty(),
        "--compilers {compilers}: none of the GPU models asked ({}) has a compiler here that reports its \
         occupancy (those that do: {})",
        gpus.iter().map(|g| g.id).collect::<Vec<_>>().join(", "),
        gpus::GPUS.iter().filter(|g| g.compiler.is_some()).map(|g| g.id).collect::<Vec<_>>().join(", ")
    );
    // A model the release has no compiler for (Debian's newest Mesa has no panvk) is left out,
    // said: its GPU keeps the assumed figure. Compilers not installed at all are refused.
    if names.iter().any(|n| crate::vendor::find_model(n).is_some()) {
        let choice = Some(compilers).filter(|c| *c != "pinned");
        let dir = isa::shim::compilers_for(choice).map_err(|e| anyhow::anyhow!("--compilers {compilers}: {e}"))?;
        let (kept, lacking): (Vec<String>, Vec<String>) = names.into_iter().partition(|n| {
            crate::vendor::find_model(n).is_none() || isa::shim::check_models(&dir, std::slice::from_ref(n)).is_ok()
        });
        if !lacking.is_empty() {
            eprintln!(
                "note: --compilers {compilers} has no compiler for {}: their GPUs keep the assumed resident waves",
                lacking.join(", ")
            );
        }
        names = kept;
    }
    if names.is_empty() {
        return Ok(Vec::new());
    }
    let exe = std::env::current_exe()?;
    let targets = isa::release_targets(&names, &exe, false, Some(compilers), false)
        .map_err(|e| anyhow::anyhow!("--compilers {compilers}: {e:#}"))?;
    let matrix = isa::Matrix::Singles;
    let cfg = isa::Config {
        targets,
        matrix,
        layouts: layouts.to_vec(),
        branchings: branchings.to_vec(),
        disasm: None,
        validation: false,
        releases: 1,
    };
    let t0 = Instant::now();
    let s = isa::run(&cfg, &exe, |_| {})?;
    for n in &s.notes {
        eprintln!("note: {n}");
    }
    outln!(
        "{} single-ray kernels built on {} for their occupancy in {:.1} s",
        s.rows.len(),
        names.join(", "),
        t0.elapsed().as_secs_f64()
    );
    Ok(s.rows)
}

/// With `--estimate` and `--compilers` both: the estimate's rows of a family built here must
/// name the same compilers release, or its issue bound and the cache model's waves would come
/// from two compilers.
fn check_estimate_release(
    rows: &[crate::report::isa::IsaRow],
    estimates: &[crate::report::estimate::RayRow],
    dir: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    use crate::report::isa::release;
    for e in estimates.iter().filter(|e| !e.driver.is_empty()) {
        if let Some(r) = rows.iter().find(|r| r.family == e.family) {
            let (a, b) = (release(&e.driver), release(&r.driver));
            anyhow::ensure!(
                a == b,
                "--estimate {}: its {} rows were built on {a}, --compilers on {b}: estimate on the same release \
                 (`halftrace estimate --compilers …`)",
                dir.map_or(String::new(), |d| d.display().to_string()),
                e.family
            );
        }
    }
    Ok(())
}
