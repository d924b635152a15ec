//! `halftrace device-report`: a device's whole report in one budgeted, resumable command.

use super::outln;
use super::{bench::BenchArgs, conformance::ConformanceArgs, defaults, devices::DevicesArgs};
use super::{isa::IsaArgs, sweep::SweepArgs};
use crate::argv::Argv;
use crate::devreport::{self, Child, Options};
use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct DeviceReportArgs {
    /// Vulkan device: index or name substring (default: the device every command picks).
    #[arg(long)]
    pub device: Option<String>,
    /// Wall time for the whole report (seconds, or e.g. 90s, 8m, 1h): the fixed steps run whole,
    /// the sweep gets what remains (at least one job).
    #[arg(long, default_value = "8m", value_parser = |s: &str| crate::units::parse_duration("--budget", s))]
    pub budget: f64,
    /// Output folder (default REPORTS/<device name>). One that holds files is refused unless
    /// --resume or --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The folder the default --out is made in.
    #[arg(long, default_value = "reports", conflicts_with = "out")]
    pub reports: PathBuf,
    /// Scenes: the first (default: the bundled scene) gets conformance, the bench and the
    /// default matrix; the others are swept after it while the budget lasts. On a GPU the first
    /// is also swept instanced to at least 300k triangles, right after it.
    #[arg(long)]
    pub scene: Vec<PathBuf>,
    /// Also sweep every .obj / .obj.gz scene in this folder, after --scene (default:
    /// tests/scenes, the repository's test scenes, when run from the repository root, else
    /// ../shared/scenes when it exists; "none" for none).
    #[arg(long)]
    pub scenes_dir: Option<PathBuf>,
    /// Image size of the bench's and the sweep's rays (default 256 × 256 on a CPU device such
    /// as lavapipe, 1024 × 1024 on a GPU).
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Finish the report in --out: run only the steps that did not finish (the sweep resumes);
    /// a folder with no report yet gets a new one.
    #[arg(long)]
    pub resume: bool,
    /// Replace the report's own files in --out (other files there are left alone).
    #[arg(long)]
    pub force: bool,
    /// Treat a device feature as missing in every step (testing).
    #[arg(long, hide = true)]
    pub mask_feature: Vec<String>,
}

pub fn device_report(a: &DeviceReportArgs) -> anyhow::Result<()> {
    let mut scenes = a.scene.clone();
    if scenes.is_empty() {
        scenes.push(PathBuf::from(crate::sweep::DEFAULT_SCENE));
    }
    let dir = match &a.scenes_dir {
        Some(d) if d.as_os_str() == "none" => None,
        Some(d) => Some(d.clone()),
        None => crate::scene::default_scenes_dir(),
    };
    if let Some(d) = dir {
        let found = crate::scene::obj_files_in(&d).with_context(|| format!("--scenes-dir {}", d.display()))?;
        // A scene named twice (the bundled teapot may also be in the folder) is swept once.
        for f in found {
            let same = |s: &PathBuf| {
                crate::fsx::same_file(s, &f) || crate::scene::scene_name(s) == crate::scene::scene_name(&f)
            };
            if !scenes.iter().any(same) {
                scenes.push(f);
            }
        }
    }
    let opts = Options {
        device: a.device.clone(),
        budget_s: a.budget,
        out: a.out.clone(),
        reports: a.reports.clone(),
        scenes,
        width: a.width,
        height: a.height,
        resume: a.resume,
        force: a.force,
        mask_features: a.mask_feature.clone(),
        argv: child_argv,
    };
    let exe = std::env::current_exe().context("finding this binary (each step runs it)")?;
    let t0 = std::time::Instant::now();
    let s = devreport::run(&opts, &exe, |step| {
        eprintln!("device-report: {step} ({:.0} s elapsed)", t0.elapsed().as_secs_f64());
    })?;
    for name in devreport::STEPS {
        if let Some(st) = s.state.steps.get(*name) {
            outln!("{name:<12} {:>6.0} s  {}", st.seconds, st.status);
        }
    }
    outln!(
        "{}: {} of {} sweep jobs; {:.0} s; report: {}",
        s.state.device,
        s.sweep_rows,
        s.sweep_jobs,
        s.seconds,
        s.out.join("report.md").display()
    );
    let failed: Vec<&str> =
        s.state.steps.iter().filter(|(_, st)| st.status.starts_with("failed")).map(|(n, _)| n.as_str()).collect();
    anyhow::ensure!(
        failed.is_empty(),
        "step(s) failed: {} (their logs are in {})",
        failed.join(", "),
        s.out.join("logs").display()
    );
    Ok(())
}

/// A report step's command line, built from the command's own arguments.
fn child_argv(c: &Child) -> Argv {
    use super::Cmd;
    match child_args(c) {
        Cmd::Devices(a) => a.argv(),
        Cmd::Conformance(a) => a.argv(),
        Cmd::Bench(a) => a.argv(),
        Cmd::Sweep(a) => a.argv(),
        Cmd::Isa(a) => a.argv(),
        other => unreachable!("no report step runs {other:?}"),
    }
}

/// A report step as its command's typed arguments.
fn child_args(c: &Child) -> super::Cmd {
    use super::Cmd;
    match c.clone() {
        Child::Devices { mask_features } => {
            Cmd::Devices(DevicesArgs { mask_feature: mask_features, ..defaults("devices") })
        }
        Child::Conformance { scene, device, mask_features, out } => Cmd::Conformance(ConformanceArgs {
            quick: true,
            scene: vec![scene],
            device: Some(device),
            mask_feature: mask_features,
            out: Some(out),
            force: true,
            ..defaults("conformance")
        }),
        Child::Bench { scene, device, rays, rounds, repeat, width, height, out } => Cmd::Bench(BenchArgs {
            scene: vec![scene],
            rays,
            rounds,
            repeat,
            width,
            height,
            device: Some(device),
            out: Some(out),
            ..defaults("bench")
        }),
        Child::Sweep {
            scenes,
            device,
            mask_features,
            width,
            height,
            kernel_timeout_s,
            budget_s,
            out,
            resume,
            force,
        } => Cmd::Sweep(SweepArgs {
            scene: scenes,
            device: Some(device),
            mask_feature: mask_features,
            width: Some(width),
            height: Some(height),
            kernel_timeout: Some(kernel_timeout_s),
            budget: Some(budget_s),
            out: Some(out),
            resume,
            force,
            quiet: true,
            ..defaults("sweep")
        }),
        Child::Isa { device, out } => {
            Cmd::Isa(IsaArgs { device: vec![device], out: Some(out), force: true, quiet: true, ..defaults("isa") })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rays::RayKind;
    use clap::Parser;

    /// Each step's command line parses back, with clap, into the arguments it was built from.
    #[test]
    fn each_steps_command_parses_back() {
        let p = |s: &str| PathBuf::from(s);
        let mask = vec!["shaderFloat16".to_string()];
        for c in [
            Child::Devices { mask_features: mask.clone() },
            Child::Conformance { scene: p("-odd.obj"), device: "1".into(), mask_features: mask.clone(), out: p("o/c") },
            Child::Bench {
                scene: p("a b.obj"),
                device: "0".into(),
                rays: vec![RayKind::Primary, RayKind::Ao],
                rounds: 3,
                repeat: 3,
                width: 320,
                height: 200,
                out: p("o/bench.md"),
            },
            Child::Sweep {
                scenes: vec![p("a.obj"), p("b,c.glb")],
                device: "0".into(),
                mask_features: mask.clone(),
                width: 64,
                height: 48,
                kernel_timeout_s: 120.0,
                budget_s: 61.3,
                out: p("o/sweep"),
                resume: true,
                force: false,
            },
            Child::Isa { device: "2".into(), out: p("o/sweep") },
        ] {
            let want = child_args(&c);
            let argv = child_argv(&c).0;
            let got =
                crate::commands::Cli::try_parse_from(std::iter::once("halftrace".to_string()).chain(argv.clone()))
                    .unwrap_or_else(|e| panic!("{c:?}: {argv:?} does not parse: {e}"));
            assert_eq!(got.cmd, want, "{c:?}: {argv:?}");
        }
    }
}
