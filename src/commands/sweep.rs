//! `halftrace sweep`: the configuration from `--config` and flags, the output folder checked,
//! then the sweep.

use super::outln;
use crate::cli::SweepArgs;
use crate::outdir::{self, OutDir, OutMode};
use crate::sweep::{self, Config, Shard, Sweep};
use std::time::Instant;

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
