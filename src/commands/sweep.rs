//! `halftrace sweep`: the configuration from `--config` and flags, the output folder checked,
//! then the sweep.

use super::outln;
use crate::argv::Argv;
use crate::outdir::{self, OutDir, OutMode};
use crate::sweep::{self, Config, Shard, Sweep};
use std::time::Instant;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct SweepArgs {
    /// TOML file with any of the keys of sweep.example.toml; flags override it.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Scene file (repeat for several).
    #[arg(long)]
    pub scene: Vec<std::path::PathBuf>,
    /// Ray kinds, comma-separated (primary, ao, diffuse, grazing, FILE.npy).
    #[arg(long, value_delimiter = ',')]
    pub rays: Vec<String>,
    /// Layouts and baselines, comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<String>,
    /// Layouts that get the B and P series, comma-separated (default f32,f16h; "all" for
    /// every layout in --layouts); the others run at --layout-branchings only.
    #[arg(long, value_delimiter = ',')]
    pub series: Vec<String>,
    /// Branching factors swept at P = 1 (series layouts).
    #[arg(long, value_delimiter = ',')]
    pub branchings: Vec<usize>,
    /// Branching factors at which every layout runs with P = 1 (default 4,8).
    #[arg(long, value_delimiter = ',', alias = "scheme-branchings")]
    pub layout_branchings: Vec<usize>,
    /// Packet sizes swept at B = --packet-branching.
    #[arg(long, value_delimiter = ',')]
    pub packets: Vec<usize>,
    #[arg(long)]
    pub packet_branching: Option<usize>,
    /// Math modes, comma-separated: f16, f32, mixed.
    #[arg(long, value_delimiter = ',')]
    pub maths: Vec<String>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    #[arg(long)]
    pub warmup: Option<usize>,
    #[arg(long)]
    pub repeat: Option<usize>,
    #[arg(long)]
    pub seed: Option<u64>,
    #[arg(long)]
    pub device: Option<String>,
    /// Output folder (default reports/<UTC timestamp>/). A folder that already holds files is
    /// refused unless --resume or --force.
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Run share K of N of the job list (1 <= K <= N; deterministic, balanced by expected
    /// cost) into --out/shard-K-of-N; merge the shards with `halftrace report`. Inside a Slurm
    /// job array it defaults to the array task (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT).
    #[arg(long)]
    pub shard: Option<String>,
    /// Wall-time budget (seconds, or e.g. 90s, 8m, 1h30m): no job starts once the time so far
    /// plus the longest job so far would pass it (the first job always runs); --resume runs
    /// the rest.
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--budget", s))]
    pub budget: Option<f64>,
    /// Continue the sweep in --out: keep its rows, run only the jobs they do not record.
    #[arg(long)]
    pub resume: bool,
    /// Replace the sweep's files in --out (other files there are left alone).
    #[arg(long)]
    pub force: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Float-control modes of the kernels: auto, on or off (see `trace --help`).
    #[arg(long)]
    pub float_controls: Option<crate::precision::FcChoice>,
    /// Treat a device feature as missing (testing), e.g. rayQuery.
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
    /// How long a dispatch may run before its kernel is declared hung: seconds or e.g. 90s,
    /// 10m (default 600 s; at most a week).
    #[arg(long, value_parser = |s: &str| crate::units::parse_duration("--kernel-timeout", s))]
    pub kernel_timeout: Option<f64>,
}

impl SweepArgs {
    /// This command's line, every argument as set.
    pub fn argv(&self) -> Argv {
        let path = |p: &Option<std::path::PathBuf>| p.as_ref().map(|p| p.display().to_string());
        Argv::new("sweep")
            .opt("config", path(&self.config))
            .each("scene", self.scene.iter().map(|p| p.display()))
            .list("rays", &self.rays)
            .list("layouts", &self.layouts)
            .list("series", &self.series)
            .list("branchings", &self.branchings)
            .list("layout-branchings", &self.layout_branchings)
            .list("packets", &self.packets)
            .opt("packet-branching", self.packet_branching)
            .list("maths", &self.maths)
            .opt("width", self.width)
            .opt("height", self.height)
            .opt("warmup", self.warmup)
            .opt("repeat", self.repeat)
            .opt("seed", self.seed)
            .opt("device", self.device.as_ref())
            .opt("out", path(&self.out))
            .opt("shard", self.shard.as_ref())
            .opt("budget", self.budget)
            .flag("resume", self.resume)
            .flag("force", self.force)
            .flag("quiet", self.quiet)
            .opt(
                "float-controls",
                self.float_controls
                    .and_then(|f| clap::ValueEnum::to_possible_value(&f))
                    .map(|v| v.get_name().to_string()),
            )
            .each("mask-feature", &self.mask_feature)
            .opt("kernel-timeout", self.kernel_timeout)
    }
}

/// The sweep's configuration: the file's (or the defaults), each flag given over it, checked.
fn config(a: &SweepArgs) -> anyhow::Result<Sweep> {
    let mut c = match &a.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    fn set<T: Clone>(dst: &mut Vec<T>, src: &[T]) {
        if !src.is_empty() {
            *dst = src.to_vec();
        }
    }
    set(&mut c.scenes, &a.scene);
    set(&mut c.rays, &a.rays);
    set(&mut c.layouts, &a.layouts);
    set(&mut c.branchings, &a.branchings);
    set(&mut c.layout_branchings, &a.layout_branchings);
    set(&mut c.packets, &a.packets);
    set(&mut c.maths, &a.maths);
    if !a.series.is_empty() {
        c.series = if a.series == ["all"] { c.layouts.clone() } else { a.series.clone() };
    }
    c.packet_branching = a.packet_branching.unwrap_or(c.packet_branching);
    c.width = a.width.unwrap_or(c.width);
    c.height = a.height.unwrap_or(c.height);
    c.warmup = a.warmup.unwrap_or(c.warmup);
    c.repeat = a.repeat.unwrap_or(c.repeat);
    c.seed = a.seed.unwrap_or(c.seed);
    c.kernel_timeout = a.kernel_timeout.unwrap_or(c.kernel_timeout);
    c.device = a.device.clone().unwrap_or(c.device);
    c.float_controls = a.float_controls.unwrap_or(c.float_controls);
    c.budget = a.budget;
    let mut s = c.check()?;
    s.shard = match &a.shard {
        Some(s) => Some(s.parse().map_err(anyhow::Error::msg)?),
        None => Shard::from_slurm(|k| std::env::var(k).ok()).map_err(anyhow::Error::msg)?,
    };
    Ok(s)
}

pub fn sweep(a: &SweepArgs) -> anyhow::Result<()> {
    let c = config(a)?;
    let mut out = a.out.clone().unwrap_or_else(|| outdir::default_out(None));
    if let Some(s) = c.shard {
        out = out.join(s.folder());
    }
    let mode = OutMode::from_flags(a.resume, a.force)?;
    // One writer per folder (a shard's own): a second run would rewrite results.csv without
    // this one's rows.
    let claimed = OutDir::claim_for(&out, "--out", mode, &sweep::OUTPUTS)?;
    let kept = sweep::prepare_out(&claimed)?;
    crate::progress::set_quiet(a.quiet);
    let t0 = Instant::now();
    let s = sweep::run(&c, &out, a.quiet, &a.mask_feature, kept)?;
    outln!("{} variants in {:.0} s; report: {}", s.rows, t0.elapsed().as_secs_f64(), s.out.join("report.md").display());
    if s.unrun > 0 {
        outln!(
            "budget of {:.0} s reached: {} job(s) not run; rerun with --resume to run them",
            c.budget.unwrap_or(0.0),
            s.unrun
        );
    }
    anyhow::ensure!(s.failed.is_empty(), "{} variant(s) failed validation: {}", s.failed.len(), s.failed.join(", "));
    Ok(())
}
