//! `halftrace conformance`: which variants are correct on this device. Every layout × B × P ×
//! math × float-control mode × packet implementation (or, `--quick`, a subset that still
//! touches each value of each of them once) runs over every scene and ray kind through the
//! runner and is compared with the CPU reference of its layout, packet size and math: hits
//! bit for bit, counters exactly (float controls on) or within
//! [`crate::runner::measure::FC_OFF_COUNTER_BOUND`] (off, where the device's own rounding may
//! move a box test by an ulp), and hits equal to the `f32` reference's. The result is a
//! table naming any failing variant, ray and both results.

use crate::base::Status;
use crate::gpu::{self, support, Gpu};
use crate::layout::LayoutId;
use crate::precision::{FcChoice, FloatControls};
use crate::rays::{RayKind, RayParams};
use crate::runner::{Plan, RaySpec, Runner, Target};
use crate::variant::{self, KernelId, KernelSpec, Matrix, PacketImpl, Variant};
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to check.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// The covering subset instead of the full cross product.
    pub quick: bool,
    pub scenes: Vec<PathBuf>,
    pub device: Option<String>,
    pub mask_features: Vec<String>,
    /// Run with the Khronos validation layer (any message fails the run).
    pub validation: bool,
}

/// One checked kernel: a variant in one packet implementation.
#[derive(Clone, Debug)]
pub struct Check {
    pub variant: Variant,
    pub imp: PacketImpl,
    pub status: Status,
    /// Rays compared (over every scene and ray kind).
    pub rays: usize,
    /// Rays whose counters differed from the reference (allowed only with float controls off).
    pub counter_diffs: usize,
    /// Rays the kernel flagged for the exact re-trace (fp32 could not decide them).
    pub flagged: usize,
    pub secs: f64,
}

/// A finished run.
pub struct Outcome {
    pub device: String,
    pub driver: String,
    pub scenes: Vec<String>,
    pub checks: Vec<Check>,
    pub validation: Vec<String>,
    pub secs: f64,
}

impl Outcome {
    pub fn failures(&self) -> Vec<&Check> {
        self.checks.iter().filter(|c| c.status.is_failed()).collect()
    }
    pub fn passed(&self) -> bool {
        self.failures().is_empty() && self.validation.is_empty()
    }
}

/// The kernels to check on a device, in run order (each exactly: float controls and packet
/// implementation as given): [`Matrix::Full`] or, quick, [`Matrix::Cover`], each packet size in
/// the implementations the device can run. In the quick set, packets a subgroup holds check
/// shared memory and the device's own implementation (subgroup, or hybrid without clustered
/// operations), larger ones the device's default, so each implementation is covered once per
/// layout. Float controls on are asked for as auto: on a device without the float controls a
/// kernel declares, its build without them is checked in its place where the layout has one
/// (so a device like SwiftShader checks f32 at every B and P, not only the two builds without
/// float controls of the quick set).
pub fn plan(info: &gpu::DeviceInfo, quick: bool) -> Vec<KernelSpec> {
    let imps = |p: usize| -> Vec<Option<PacketImpl>> {
        let plan = support::packet_plan(info, p).0;
        let hybrid = support::has_subgroup_arithmetic(info);
        // A subgroup holds the packet, but the device lacks clustered operations: hybrid.
        let held = support::subgroup_holds(info, p);
        let imps = match plan {
            PacketImpl::Single => vec![PacketImpl::Single],
            PacketImpl::Subgroup if quick => vec![PacketImpl::Shared, PacketImpl::Subgroup],
            PacketImpl::Subgroup if hybrid => vec![PacketImpl::Shared, PacketImpl::Subgroup, PacketImpl::Hybrid],
            PacketImpl::Subgroup => vec![PacketImpl::Shared, PacketImpl::Subgroup],
            PacketImpl::Hybrid if quick && held => vec![PacketImpl::Shared, PacketImpl::Hybrid],
            PacketImpl::Hybrid if quick => vec![PacketImpl::Hybrid],
            PacketImpl::Hybrid => vec![PacketImpl::Shared, PacketImpl::Hybrid],
            PacketImpl::Shared => vec![PacketImpl::Shared],
        };
        imps.into_iter().map(Some).collect()
    };
    let m = if quick { Matrix::Cover } else { Matrix::Full };
    let mut seen = std::collections::HashSet::new();
    variant::matrix(m, &imps)
        .into_iter()
        .map(|k| {
            let imp = k.imp.unwrap_or(PacketImpl::Single);
            let v = match k.fc {
                // On or auto: the build with float controls where the device runs it, else
                // the one without.
                FcChoice::On | FcChoice::Auto => {
                    support::resolve(info, k.variant, FcChoice::Auto).unwrap_or(k.variant.with_fc(FloatControls::On))
                }
                FcChoice::Off => k.variant.with_fc(FloatControls::Off),
            };
            KernelSpec::exact(v, imp)
        })
        .filter(|k| seen.insert(k.clone()))
        .collect()
}

/// The ray sets of every scene: primary, ao and diffuse at `res`², and grazing rays.
fn ray_specs(quick: bool) -> Vec<RaySpec> {
    let (res, grazing) = if quick { (16, 256) } else { (32, 1000) };
    let params = RayParams { width: res, height: res, camera: None, seed: 7, grazing };
    [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing]
        .into_iter()
        .map(|kind| RaySpec { kind, params: params.clone() })
        .collect()
}

/// The kernel target of a check: its variant with its float controls as given, in its packet
/// implementation.
fn target(c: &Check) -> Target {
    Target::Kernel(KernelSpec::exact(c.variant, c.imp))
}

/// Runs the checks; `progress` gets a line as each scene finishes.
pub fn run(opts: &Options, mut progress: impl FnMut(&str)) -> anyhow::Result<Outcome> {
    let t0 = Instant::now();
    anyhow::ensure!(!opts.scenes.is_empty(), "conformance needs at least one scene");
    let g = Gpu::new(&gpu::ContextOptions {
        device: opts.device.clone(),
        mask_features: opts.mask_features.clone(),
        validation: opts.validation,
        ..Default::default()
    })?;
    let mut checks: Vec<Check> = plan(&g.info, opts.quick)
        .into_iter()
        .map(|k| {
            let (variant, imp) = (k.variant, k.imp.expect("planned exactly"));
            let status =
                support::admit(&g.info, &KernelId::new(variant, imp, false)).err().map_or(Status::Ok, Status::Skipped);
            Check { variant, imp, status, rays: 0, counter_diffs: 0, flagged: 0, secs: 0.0 }
        })
        .collect();
    progress(&format!("{} kernels on {}", checks.len(), g.info.name));
    let mut runner = Runner::new(Some(&g), &[], Default::default())?;
    let admitted: Vec<KernelSpec> =
        checks.iter().filter(|c| c.status.is_ok()).map(|c| KernelSpec::exact(c.variant, c.imp)).collect();
    let mut scene_names = Vec::new();
    for path in &opts.scenes {
        let name = runner.scene(path)?.0.name.clone();
        let mut sets = Vec::new();
        for spec in ray_specs(opts.quick) {
            let id = runner.ray_set(&spec).with_context(|| format!("{} {} rays", path.display(), spec.kind))?;
            sets.push((spec.kind, id));
        }
        // Built (on lavapipe: compiled) once the first scene and its rays have loaded, so that
        // a scene that does not load is reported at once.
        if scene_names.is_empty() {
            runner.prebuild(&admitted);
            progress(&format!("{} kernels built ({:.0} s)", admitted.len(), t0.elapsed().as_secs_f64()));
        }
        // Each encoding (layout × B) stays on the device while its checks run.
        let mut keys: Vec<(LayoutId, usize)> =
            checks.iter().filter(|c| c.status.is_ok()).map(|c| (c.variant.layout, c.variant.branching)).collect();
        keys.sort();
        keys.dedup();
        for (layout, b) in keys {
            for c in
                checks.iter_mut().filter(|c| c.status.is_ok() && (c.variant.layout, c.variant.branching) == (layout, b))
            {
                let t = Instant::now();
                for (kind, set) in &sets {
                    let what = format!("{name} {kind}");
                    match runner.measure(&target(c), *set, Plan::VALIDATE) {
                        Ok(o) => match o.status {
                            Status::Ok => {
                                c.rays += runner.rays(*set).rays.len();
                                c.counter_diffs += o.m.counter_diffs;
                                c.flagged += o.m.flagged;
                            }
                            Status::Failed(f) => c.status = Status::Failed(format!("{what}: {f}")),
                            Status::Skipped(why) => c.status = Status::Skipped(why),
                        },
                        Err(e) => c.status = Status::Failed(format!("{what}: {e:#}")),
                    }
                    if !c.status.is_ok() {
                        break;
                    }
                }
                c.secs += t.elapsed().as_secs_f64();
            }
            runner.release(layout, b);
        }
        scene_names.push(name.clone());
        let fails = checks.iter().filter(|c| c.status.is_failed()).count();
        progress(&format!(
            "scene {}/{} {name} checked ({fails} failing kernels so far, {:.0} s)",
            scene_names.len(),
            opts.scenes.len(),
            t0.elapsed().as_secs_f64()
        ));
    }
    drop(runner);
    let validation = g.validation_messages();
    Ok(Outcome {
        device: g.info.name.clone(),
        driver: g.info.driver.clone(),
        scenes: scene_names,
        checks,
        validation,
        secs: t0.elapsed().as_secs_f64(),
    })
}

/// The table of every check (Markdown).
pub fn markdown(o: &Outcome, quick: bool) -> String {
    let fails = o.failures().len();
    let skipped = o.checks.iter().filter(|c| c.status.is_skipped()).count();
    let (res, grazing) = if quick { (16, 256) } else { (32, 1000) };
    let mut md = format!("# Conformance on {}\n\n- driver: {}\n", o.device, o.driver);
    let run = if quick { "quick" } else { "full" };
    md += &format!(
        "- halftrace {} ({}), {run} run, {:.0} s\n",
        env!("CARGO_PKG_VERSION"),
        env!("HALFTRACE_COMMIT"),
        o.secs
    );
    md += &format!(
        "- scenes: {}\n- rays per scene: primary, ao, diffuse at {res}², {grazing} grazing\n",
        o.scenes.join(", ")
    );
    let ok = o.checks.len() - fails - skipped;
    md += &format!("- {} kernels: {ok} ok, {fails} FAILED, {skipped} skipped\n", o.checks.len());
    md += &format!("- validation layer messages: {}\n\n", o.validation.len());
    md += concat!(
        "Each kernel is compared with the CPU reference of its layout, packet size and math: hits bit for bit ",
        "(and equal to the f32 reference's), counters exactly with float controls on, on all but 1% of rays with ",
        "them off.\n\n"
    );
    md += "| kernel | layout | math | B | P | implementation | float controls | rays | counter diffs | flagged | s | status |\n|---|---|---|---:|---:|---|---|---:|---:|---:|---:|---|\n";
    for c in &o.checks {
        let v = c.variant;
        md += &format!(
            "| {} | {} | {} | {} | {} | {:?} | {} | {} | {} | {} | {:.1} | {} |\n",
            v.kernel_name(c.imp, false),
            v.layout,
            v.math.name(),
            v.branching,
            v.packet,
            c.imp,
            v.fc.name(),
            c.rays,
            c.counter_diffs,
            c.flagged,
            c.secs,
            c.status.to_string().replace('|', "/")
        );
    }
    for m in &o.validation {
        md += &format!("\nvalidation: {m}\n");
    }
    md
}

/// One line of `conformance.csv`.
#[derive(serde::Serialize)]
struct Record<'a> {
    kernel: String,
    layout: &'a str,
    math: &'a str,
    branching: usize,
    packet: usize,
    implementation: String,
    float_controls: &'a str,
    rays: usize,
    counter_diffs: usize,
    flagged: usize,
    #[serde(serialize_with = "crate::report::csvx::fixed::<3, _>")]
    seconds: f64,
    #[serde(serialize_with = "crate::report::csvx::display")]
    status: &'a Status,
    device: &'a str,
    driver: &'a str,
}

/// Writes `conformance.md` and `conformance.csv` into `dir` (each through a temporary file
/// renamed into place).
pub fn write(o: &Outcome, quick: bool, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let records = o.checks.iter().map(|c| Record {
        kernel: c.variant.kernel_name(c.imp, false),
        layout: c.variant.layout.name(),
        math: c.variant.math.name(),
        branching: c.variant.branching,
        packet: c.variant.packet,
        implementation: format!("{:?}", c.imp),
        float_controls: c.variant.fc.name(),
        rays: c.rays,
        counter_diffs: c.counter_diffs,
        flagged: c.flagged,
        seconds: c.secs,
        status: &c.status,
        device: &o.device,
        driver: &o.driver,
    });
    let bytes = crate::report::csvx::to_bytes(records)?;
    for (name, data) in [("conformance.csv", bytes), ("conformance.md", markdown(o, quick).into_bytes())] {
        crate::fsx::write_atomic(&dir.join(name), &data)?;
    }
    Ok(())
}
