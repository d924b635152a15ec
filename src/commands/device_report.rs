//! `halftrace device-report`: a device's whole report in one budgeted, resumable command.

use super::outln;
use crate::cli::DeviceReportArgs;
use crate::devreport::{self, Options};
use anyhow::Context;
use std::path::PathBuf;

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
