//! `halftrace bench`: the speed ratios a kernel change is judged by.

use super::outln;
use crate::bench::{self, BenchConfig};
use crate::cli::{BenchArgs, LayoutArg};
use crate::rays::RayKind;
use anyhow::Context as _;
use std::path::PathBuf;

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
