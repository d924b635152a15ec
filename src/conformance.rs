//! `halftrace conformance`: which variants are correct on this device. Every layout × B × P ×
//! math × float-control mode × packet implementation (or, `--quick`, a subset that still
//! touches each value of each of them once) runs over every scene and ray kind and is compared
//! with the CPU reference of its layout, packet size and math: hits bit for bit, counters
//! exactly (float controls on) or within [`FC_OFF_COUNTER_BOUND`] (off, where the device's own
//! rounding may move a box test by an ulp), and hits equal to the `f32` reference's. The
//! result is a pass/fail table naming any failing variant, ray and both results.

use crate::bvh::{self, BinaryBvh, BRANCHINGS};
use crate::gpu::kernel::{GpuBvh, Kernel, Source};
use crate::gpu::{self, support, Gpu};
use crate::layout::{Encoded, LayoutId};
use crate::rays::{make_rays, Ray, RayKind, RayParams};
use crate::scene::Scene;
use crate::trace::{Counters, Hit};
use crate::variant::{Buffers, FloatControls, PacketImpl, Variant, PACKETS};
use anyhow::Context;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// With float controls off, a device may round box-test arithmetic differently from the CPU
/// reference (the bounds stay conservative, so hits are exact): counters may then differ on at
/// most this fraction of a ray set's rays.
pub const FC_OFF_COUNTER_BOUND: f64 = 0.01;

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
    pub secs: f64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    Pass,
    Fail(String),
    Skipped(String),
}

impl Status {
    pub fn label(&self) -> String {
        match self {
            Status::Pass => "pass".into(),
            Status::Fail(m) => format!("FAIL: {m}"),
            Status::Skipped(m) => format!("skipped: {m}"),
        }
    }
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
        self.checks.iter().filter(|c| matches!(c.status, Status::Fail(_))).collect()
    }
    pub fn passed(&self) -> bool {
        self.failures().is_empty() && self.validation.is_empty()
    }
}

/// The kernels to check on a device, in run order. Full: every layout × math × float-control
/// build the layout has × B × P, each packet size in every implementation the device can run.
/// Quick: per layout, every B at P = 1 in the default math, every other math once, every P at
/// B = 4 (the math modes in turn), both implementations at every P the subgroup holds, and the
/// build without float controls in every math mode at P = 1 and in a packet where the layout
/// has one.
pub fn plan(info: &gpu::DeviceInfo, quick: bool) -> Vec<(Variant, PacketImpl)> {
    let mut out: Vec<(Variant, PacketImpl)> = Vec::new();
    // Every implementation the device can run at P; in the quick set, packets a subgroup
    // holds check shared memory and subgroups, larger ones the device's default (hybrid
    // where it has subgroup arithmetic), so each implementation is covered once per layout.
    let imps = |p: usize| -> Vec<PacketImpl> {
        let plan = support::packet_plan(info, p).0;
        let hybrid = support::has_subgroup_arithmetic(info);
        match plan {
            PacketImpl::Single => vec![PacketImpl::Single],
            PacketImpl::Subgroup if quick => vec![PacketImpl::Shared, PacketImpl::Subgroup],
            PacketImpl::Subgroup if hybrid => vec![PacketImpl::Shared, PacketImpl::Subgroup, PacketImpl::Hybrid],
            PacketImpl::Subgroup => vec![PacketImpl::Shared, PacketImpl::Subgroup],
            PacketImpl::Hybrid if quick => vec![PacketImpl::Hybrid],
            PacketImpl::Hybrid => vec![PacketImpl::Shared, PacketImpl::Hybrid],
            PacketImpl::Shared => vec![PacketImpl::Shared],
        }
    };
    for layout in LayoutId::layouts() {
        let l = layout.bvh().expect("a BVH layout");
        let maths = layout.caps().maths;
        let fcs: Vec<FloatControls> =
            if l.float_controls_off() { vec![FloatControls::On, FloatControls::Off] } else { vec![FloatControls::On] };
        if quick {
            for b in BRANCHINGS {
                out.push((Variant::new(layout, b, 1), PacketImpl::Single));
            }
            for (i, &m) in maths.iter().enumerate().skip(1) {
                out.push((Variant::new(layout, BRANCHINGS[i % BRANCHINGS.len()], 1).with_math(m), PacketImpl::Single));
            }
            for (j, p) in PACKETS.into_iter().filter(|&p| p > 1).enumerate() {
                let v = Variant::new(layout, 4, p).with_math(maths[j % maths.len()]);
                out.extend(imps(p).into_iter().map(|imp| (v, imp)));
            }
            if fcs.contains(&FloatControls::Off) {
                for (i, &m) in maths.iter().enumerate() {
                    out.push((
                        Variant::new(layout, BRANCHINGS[(i + 1) % BRANCHINGS.len()], 1)
                            .with_math(m)
                            .with_fc(FloatControls::Off),
                        PacketImpl::Single,
                    ));
                }
                let v = Variant::new(layout, 8, 8).with_math(maths[maths.len() - 1]).with_fc(FloatControls::Off);
                out.extend(imps(8).into_iter().map(|imp| (v, imp)));
            }
        } else {
            for &m in maths {
                for &fc in &fcs {
                    for b in BRANCHINGS {
                        for p in PACKETS {
                            let v = Variant::new(layout, b, p).with_math(m).with_fc(fc);
                            out.extend(imps(p).into_iter().map(|imp| (v, imp)));
                        }
                    }
                }
            }
        }
    }
    out
}

/// Ray sets of one scene: primary, ao and diffuse at `res`², and `grazing` grazing rays.
fn ray_sets(scene: &Scene, bin: &BinaryBvh, quick: bool) -> anyhow::Result<Vec<(RayKind, Vec<Ray>)>> {
    let (res, grazing) = if quick { (16, 256) } else { (32, 1000) };
    let params = RayParams { width: res, height: res, camera: None, seed: 7, grazing };
    [RayKind::Primary, RayKind::Ao, RayKind::Diffuse, RayKind::Grazing]
        .into_iter()
        .map(|k| Ok((k.clone(), make_rays(scene, bin, &k, &params)?)))
        .collect()
}

/// The first rays whose hits differ, for a failure message.
fn first_diff(rays: &[Ray], want: &[Hit], got: &[Hit]) -> Option<String> {
    let bad: Vec<usize> = (0..got.len()).filter(|&i| !want[i].same_bits(&got[i])).collect();
    let &i = bad.first()?;
    Some(format!(
        "{} of {} rays differ; ray {i} {:?}: expected {:?}, got {:?}",
        bad.len(),
        got.len(),
        rays[i],
        want[i],
        got[i]
    ))
}

/// Runs the checks; `progress` gets a line as kernels are built and as each scene finishes.
pub fn run(opts: &Options, mut progress: impl FnMut(&str)) -> anyhow::Result<Outcome> {
    let t0 = Instant::now();
    anyhow::ensure!(!opts.scenes.is_empty(), "conformance needs at least one scene");
    let g = Gpu::new(&gpu::ContextOptions {
        device: opts.device.clone(),
        mask_features: opts.mask_features.clone(),
        validation: opts.validation,
        ..Default::default()
    })?;
    let plan = plan(&g.info, opts.quick);
    let mut checks: Vec<Check> = plan
        .iter()
        .map(|&(variant, imp)| {
            let status = match support::check(&g.info, &variant) {
                Ok(()) => Status::Pass,
                Err(why) => Status::Skipped(why),
            };
            Check { variant, imp, status, rays: 0, counter_diffs: 0, secs: 0.0 }
        })
        .collect();
    // Kernels (timed, counting) of every runnable check, built once per way of reaching the
    // scene's buffers (bound up front; read by address when a scene needs it).
    let pair = |v: &Variant, imp: PacketImpl| {
        Kernel::build(&g, v, imp, false, &Source::Builtin)
            .and_then(|a| Ok((a, Kernel::build(&g, v, imp, true, &Source::Builtin)?)))
    };
    let mut kernels: HashMap<(usize, Buffers), (Kernel, Kernel)> = HashMap::new();
    let total = checks.len();
    progress(&format!("{total} kernels on {}: building pipelines", g.info.name));
    for (i, c) in checks.iter_mut().enumerate() {
        if i > 0 && i % 16 == 0 {
            progress(&format!("built {i}/{total} kernels ({:.0} s)", t0.elapsed().as_secs_f64()));
        }
        if c.status != Status::Pass {
            continue;
        }
        let t = Instant::now();
        match pair(&c.variant, c.imp) {
            Ok(k) => {
                kernels.insert((i, Buffers::Bound), k);
            }
            Err(gpu::GpuError::Unsupported(why)) => c.status = Status::Skipped(why),
            Err(e) => c.status = Status::Fail(format!("building the kernel: {e}")),
        }
        c.secs += t.elapsed().as_secs_f64();
    }
    let mut scene_names = Vec::new();
    for path in &opts.scenes {
        let scene = crate::scene::load(path)?;
        let bin = bvh::build_binary(&scene);
        let sets = ray_sets(&scene, &bin, opts.quick).with_context(|| path.display().to_string())?;
        let f32_enc = Encoded::new(&scene, &bin, LayoutId::f32(), 4)?;
        let f32_hits: Vec<Vec<Hit>> = sets.iter().map(|(_, r)| f32_enc.trace_default(r).0).collect();
        // One encoding per (layout, B), uploaded while its checks run.
        let mut keys: Vec<(LayoutId, usize)> = checks
            .iter()
            .filter(|c| c.status == Status::Pass)
            .map(|c| (c.variant.layout, c.variant.branching))
            .collect();
        keys.sort();
        keys.dedup();
        for (layout, b) in keys {
            let tg = Instant::now();
            let enc = Encoded::new(&scene, &bin, layout, b)?;
            let gb = GpuBvh::upload(&g, &enc).with_context(|| format!("{} {layout} B={b}", scene.name))?;
            let mut refs: HashMap<(usize, crate::layout::Math, FloatControls, usize), (Vec<Hit>, Vec<Counters>)> =
                HashMap::new();
            for (i, c) in checks.iter_mut().enumerate() {
                if c.status != Status::Pass || c.variant.layout != layout || c.variant.branching != b {
                    continue;
                }
                let t = Instant::now();
                // A scene beyond one storage buffer is read by address: that build of the kernels.
                if let std::collections::hash_map::Entry::Vacant(slot) = kernels.entry((i, gb.buffers)) {
                    match pair(&c.variant.with_buffers(gb.buffers), c.imp) {
                        Ok(k) => {
                            slot.insert(k);
                        }
                        Err(e) => {
                            c.status =
                                Status::Fail(format!("building the kernel that reads the scene by address: {e}"));
                            continue;
                        }
                    }
                }
                let (timed, counting) = &kernels[&(i, gb.buffers)];
                let v = c.variant;
                for (k, (kind, rays)) in sets.iter().enumerate() {
                    let (hits, counters) = refs
                        .entry((v.packet, v.math, v.fc, k))
                        .or_insert_with(|| enc.trace_fc(rays, v.packet, v.math, v.fc));
                    let what = format!("{} {kind}", scene.name);
                    let result = (|| -> Result<usize, String> {
                        // A conservative layout's reference must be f32's hits (the seed's
                        // literal algorithm is checked against its own reference only).
                        if let Some(d) = first_diff(rays, &f32_hits[k], hits)
                            .filter(|_| layout.bvh().is_some_and(|l| l.conservative()))
                        {
                            return Err(format!("{what}: CPU reference vs f32: {d}"));
                        }
                        let a = timed.run(&g, &gb, rays, 0, 1).map_err(|e| format!("{what}: {e}"))?;
                        if let Some(d) = first_diff(rays, hits, &a.hits) {
                            return Err(format!("{what}: timed kernel vs CPU reference: {d}"));
                        }
                        let s = counting.run(&g, &gb, rays, 0, 1).map_err(|e| format!("{what}: {e}"))?;
                        if let Some(d) = first_diff(rays, hits, &s.hits) {
                            return Err(format!("{what}: counting kernel vs CPU reference: {d}"));
                        }
                        let gc = s.counters.unwrap_or_default();
                        let diff: Vec<usize> = (0..rays.len()).filter(|&r| gc.get(r) != counters.get(r)).collect();
                        let allowed = if v.fc == FloatControls::Off {
                            (FC_OFF_COUNTER_BOUND * rays.len() as f64) as usize
                        } else {
                            0
                        };
                        if diff.len() > allowed {
                            let r = diff[0];
                            return Err(format!(
                                "{what}: counters differ on {} of {} rays; ray {r} {:?}: GPU {:?}, CPU {:?}",
                                diff.len(),
                                rays.len(),
                                rays[r],
                                gc.get(r),
                                counters.get(r)
                            ));
                        }
                        Ok(diff.len())
                    })();
                    match result {
                        Ok(d) => {
                            c.rays += rays.len();
                            c.counter_diffs += d;
                        }
                        Err(m) => {
                            c.status = Status::Fail(m);
                            break;
                        }
                    }
                }
                c.secs += t.elapsed().as_secs_f64();
            }
            if tg.elapsed().as_secs_f64() > 10.0 {
                progress(&format!(
                    "  {} {layout} B={b}: {:.0} s (pipelines compiled on first use)",
                    scene.name,
                    tg.elapsed().as_secs_f64()
                ));
            }
        }
        scene_names.push(scene.name.clone());
        let fails = checks.iter().filter(|c| matches!(c.status, Status::Fail(_))).count();
        progress(&format!(
            "scene {}/{} {} checked ({fails} failing kernels so far, {:.0} s)",
            scene_names.len(),
            opts.scenes.len(),
            scene.name,
            t0.elapsed().as_secs_f64()
        ));
    }
    drop(kernels);
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

/// The pass/fail table (Markdown).
pub fn markdown(o: &Outcome, quick: bool) -> String {
    let fails = o.failures().len();
    let skipped = o.checks.iter().filter(|c| matches!(c.status, Status::Skipped(_))).count();
    let mut md = format!(
        "# Conformance on {}\n\n- driver: {}\n- halftrace {} ({}), {} run, {:.0} s\n- scenes: {}\n- rays per scene: primary, ao, diffuse at {r}², {g} grazing\n- {} kernels: {} pass, {fails} FAIL, {skipped} skipped\n- validation layer messages: {}\n\n",
        o.device, o.driver, env!("CARGO_PKG_VERSION"), env!("HALFTRACE_COMMIT"), if quick { "quick" } else { "full" }, o.secs, o.scenes.join(", "),
        o.checks.len(), o.checks.len() - fails - skipped, o.validation.len(),
        r = if quick { 16 } else { 32 }, g = if quick { 256 } else { 1000 },
    );
    md += "Each kernel is compared with the CPU reference of its layout, packet size and math: hits bit for bit (and equal to the f32 reference's), counters exactly with float controls on, on all but 1% of rays with them off.\n\n";
    md += "| kernel | layout | math | B | P | implementation | float controls | rays | counter diffs | s | status |\n|---|---|---|---:|---:|---|---|---:|---:|---:|---|\n";
    for c in &o.checks {
        let v = c.variant;
        md += &format!(
            "| {} | {} | {} | {} | {} | {:?} | {} | {} | {} | {:.1} | {} |\n",
            v.kernel_name(c.imp, false),
            v.layout,
            v.math.name(),
            v.branching,
            v.packet,
            c.imp,
            v.fc.name(),
            c.rays,
            c.counter_diffs,
            c.secs,
            c.status.label().replace('|', "/")
        );
    }
    for m in &o.validation {
        md += &format!("\nvalidation: {m}\n");
    }
    md
}

/// Writes `conformance.md` and `conformance.csv` into `dir` (each through a temporary file
/// renamed into place).
pub fn write(o: &Outcome, quick: bool, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record([
        "kernel",
        "layout",
        "math",
        "branching",
        "packet",
        "implementation",
        "float_controls",
        "rays",
        "counter_diffs",
        "seconds",
        "status",
        "device",
        "driver",
    ])?;
    for c in &o.checks {
        let v = c.variant;
        csv.write_record([
            v.kernel_name(c.imp, false),
            v.layout.to_string(),
            v.math.name().into(),
            v.branching.to_string(),
            v.packet.to_string(),
            format!("{:?}", c.imp),
            v.fc.name().into(),
            c.rays.to_string(),
            c.counter_diffs.to_string(),
            format!("{:.3}", c.secs),
            c.status.label(),
            o.device.clone(),
            o.driver.clone(),
        ])?;
    }
    let bytes = csv.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    for (name, data) in [("conformance.csv", bytes), ("conformance.md", markdown(o, quick).into_bytes())] {
        let path = dir.join(name);
        let tmp = dir.join(format!(".{name}.tmp"));
        std::fs::write(&tmp, data).with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, &path).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
