//! The estimate's rows as the report reads them (`halftrace estimate` writes them:
//! `estimate-rays.json`, `estimate-rays.csv`), its section of the report and its plot.

use super::csvx::{display, opt_display};
use super::key::{f32_peer, What};
use super::plots;
use super::rows::Status;
use anyhow::Context as _;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A ray's cycles split by the part of the kernel they are spent in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Split {
    /// Outside the traversal loop: the ray's set-up and the hit's write.
    pub setup: f64,
    /// The traversal loop's own blocks: entering a node, its box tests, ordering and pushing
    /// children, popping.
    pub step: f64,
    /// The child-slot loop's own blocks (where it is a loop): which children are leaves.
    pub slots: f64,
    /// The triangle loop and the loops inside it: the triangle tests.
    pub triangles: f64,
}

impl Split {
    pub fn total(&self) -> f64 {
        self.setup + self.step + self.slots + self.triangles
    }

    pub fn scaled(self, k: f64) -> Split {
        Split { setup: self.setup * k, step: self.step * k, slots: self.slots * k, triangles: self.triangles * k }
    }
}

/// One kernel on one family for one ray set.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RayRow {
    pub family: String,
    pub generation: String,
    /// The driver that built the kernel, naming its Mesa release (empty in files written before
    /// it was recorded).
    #[serde(default)]
    pub driver: String,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    /// Rays per packet (1: single rays) and the packet implementation the device builds.
    #[serde(default)]
    pub packet: usize,
    #[serde(default)]
    pub packet_impl: String,
    pub scene: String,
    pub rays: String,
    pub ray_count: u64,
    /// The wave size the kernel was compiled for (lanes in lockstep).
    pub wave: u32,
    pub status: Status,
    /// Issue-bound cycles per ray: a wave's cycles in lockstep ÷ its rays.
    pub cycles_per_ray: f64,
    /// The same if every pass lasted as long as the wave's average lane (no divergence).
    pub lane_average: f64,
    /// Per ray, by part.
    pub split: Split,
    /// Cycles per ray with ACO's weights for every branch (before the rays weighed the named
    /// ones), and its triangle part.
    #[serde(default)]
    pub aco_branches: f64,
    #[serde(default)]
    pub aco_triangles: f64,
    /// aco_branches ÷ f32's peer's.
    #[serde(default)]
    pub aco_vs_f32: Option<f64>,
    /// Which named branches the rays weighed (`rays: edges cross …`), which were left to
    /// ACO's weights and why.
    #[serde(default)]
    pub branches: String,
    /// ACO's waves per SIMD (registers and LDS).
    pub waves: f64,
    /// Rays per 1000 clocks per SIMD: ACO's throughput (`wave64_per_cycle`, its waves per SIMD
    /// hiding latency) scaled by its latency ÷ the rays' cycles per wave.
    pub rays_per_kclk: f64,
    /// cycles_per_ray ÷ f32's peer's ([`f32_peer`]) on the same family, scene and rays.
    pub vs_f32: Option<f64>,
    /// The kernel, typed: its isa row's, parsed once where rows are read.
    #[serde(skip)]
    pub what: What,
}

super::key::keyed_row!(RayRow, |r| place: [&r.family, "", &r.scene, &r.rays], float_controls: "", packet_impl: Some(&r.packet_impl));

/// Sets each row's ratio to its f32 peer's cycles per ray.
pub fn set_ratios(rows: &mut [RayRow]) {
    let ratios: Vec<Option<(f64, f64)>> = rows
        .iter()
        .map(|r| {
            f32_peer(r, rows.iter())
                .filter(|_| r.status.is_ok())
                .map(|f| (r.cycles_per_ray / f.cycles_per_ray, r.aco_branches / f.aco_branches.max(f64::MIN_POSITIVE)))
        })
        .collect();
    for (r, q) in rows.iter_mut().zip(ratios) {
        r.vs_f32 = q.map(|q| q.0);
        r.aco_vs_f32 = q.map(|q| q.1);
    }
}

/// The report's section (and estimate.md's second part): per family and ray set, each
/// kernel's estimated cycles per ray.
pub fn section(rows: &[RayRow]) -> String {
    let mut md = String::from("# Estimated cycles per ray\n\n");
    md += "ACO's model of each kernel with the trips of its traversal, child-slot and triangle loops counted on \
           real rays by the CPU reference, the lanes of a wave in lockstep (a wave makes a pass while any lane \
           does; a packet's P lanes step together). **An estimate from the compiler's model, an upper bound on one wave with no latency \
           hidden, not a measurement.** `cycles/ray`: a wave's cycles ÷ its rays; `lane avg`: the same if every \
           pass lasted as long as the wave's average lane (or packet); the split: set-up and hit write, the traversal step \
           (entering a node, box tests, ordering, stack), the child-slot loop, the triangle tests; `rays/kclk`: \
           rays per 1000 clocks per SIMD at ACO's occupancy (its throughput model scaled to these rays). \
           **Branches**: the named sides of the triangle test (past the projected miss test: `edges`; past the \
           edge functions' miss: `cross`; no usable determinant: `flat`, else `divide`; huge coordinates: `huge`; \
           not rejected by tmin or the best: `candidate`; kept as the best: `best`) run in as many of a wave's \
           triangle passes as the rays take them (any lane), found in the program by a build with a marker at the \
           start of each; the other ifs keep ACO's weights (×0.75 divergent, ×0.5 uniform). `ACO's branches`: the \
           same with ACO's weights for every branch (the figure before the rays weighed them).\n\n";
    let mut groups: Vec<(&str, &str, &str)> =
        rows.iter().map(|r| (r.family.as_str(), r.scene.as_str(), r.rays.as_str())).collect();
    groups.dedup();
    for (f, scene, kind) in groups {
        let g: Vec<&RayRow> = rows.iter().filter(|r| r.family == f && r.scene == scene && r.rays == kind).collect();
        md += &format!(
            "## {f} ({}){}, {scene}, {kind} rays ({}, wave {})\n\n",
            g[0].generation,
            if g[0].driver.is_empty() { String::new() } else { format!(", {}", super::isa::release(&g[0].driver)) },
            g[0].ray_count,
            g[0].wave
        );
        let named = |r: &&&RayRow| r.layout == "f32" && r.branches.starts_with("rays: ");
        if let Some(f) = g.iter().filter(named).find(|r| r.branching == 4 && r.packet == 1).or(g.iter().find(named)) {
            md += &format!(
                "Named branches, share of f32 {}'s triangle passes in lockstep waves (each packet or ray alone) — {}.\n\n",
                f.kernel,
                &f.branches[6..]
            );
        }
        for r in g.iter().filter(|r| r.status.is_ok() && !r.branches.starts_with("rays: ")) {
            md += &format!("- {}: {}\n", r.kernel, r.branches);
        }
        if g.iter().any(|r| r.status.is_ok() && !r.branches.starts_with("rays: ")) {
            md += "\n";
        }
        md += "| kernel | layout | math | B | P | cycles/ray | ÷ f32 | ACO's branches | ÷ f32 | lane avg | set-up | step | slots | triangles | triangles, ACO's branches | waves | rays/kclk | status |\n";
        md += "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
        for r in g {
            let ok = r.status.is_ok();
            let n = |x: f64| if ok { format!("{x:.1}") } else { "–".into() };
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.kernel,
                r.layout,
                r.math,
                r.branching,
                if r.packet > 1 { format!("{} {}", r.packet, r.packet_impl) } else { "1".into() },
                n(r.cycles_per_ray),
                r.vs_f32.map_or("–".into(), |v| format!("{v:.2}")),
                n(r.aco_branches),
                r.aco_vs_f32.map_or("–".into(), |v| format!("{v:.2}")),
                n(r.lane_average),
                n(r.split.setup),
                n(r.split.step),
                n(r.split.slots),
                n(r.split.triangles),
                n(r.aco_triangles),
                if ok { format!("{:.0}", r.waves) } else { "–".into() },
                if ok { format!("{:.2}", r.rays_per_kclk) } else { "–".into() },
                r.status
            );
        }
        md += "\n";
    }
    md
}

/// One line of `estimate-rays.csv`.
#[derive(Serialize)]
struct RayRecord<'a> {
    family: &'a str,
    generation: &'a str,
    driver: &'a str,
    kernel: &'a str,
    layout: &'a str,
    math: &'a str,
    #[serde(rename = "B")]
    branching: usize,
    #[serde(rename = "P")]
    packet: usize,
    packet_impl: &'a str,
    scene: &'a str,
    rays: &'a str,
    ray_count: u64,
    wave: u32,
    #[serde(serialize_with = "display")]
    status: &'a Status,
    #[serde(serialize_with = "display")]
    cycles_per_ray: f64,
    #[serde(serialize_with = "opt_display")]
    vs_f32: Option<f64>,
    #[serde(serialize_with = "display")]
    lane_average: f64,
    #[serde(serialize_with = "display")]
    setup: f64,
    #[serde(serialize_with = "display")]
    step: f64,
    #[serde(serialize_with = "display")]
    slots: f64,
    #[serde(serialize_with = "display")]
    triangles: f64,
    #[serde(serialize_with = "display")]
    waves: f64,
    #[serde(serialize_with = "display")]
    rays_per_kclk: f64,
    #[serde(serialize_with = "display")]
    aco_branches: f64,
    #[serde(serialize_with = "opt_display")]
    aco_vs_f32: Option<f64>,
    #[serde(serialize_with = "display")]
    aco_triangles: f64,
    branches: &'a str,
}

/// estimate-rays.csv: one line per kernel, family and ray set.
pub fn csv(rows: &[RayRow]) -> anyhow::Result<Vec<u8>> {
    super::csvx::to_bytes(rows.iter().map(|r| RayRecord {
        family: &r.family,
        generation: &r.generation,
        driver: &r.driver,
        kernel: &r.kernel,
        layout: &r.layout,
        math: &r.math,
        branching: r.branching,
        packet: r.packet,
        packet_impl: &r.packet_impl,
        scene: &r.scene,
        rays: &r.rays,
        ray_count: r.ray_count,
        wave: r.wave,
        status: &r.status,
        cycles_per_ray: r.cycles_per_ray,
        vs_f32: r.vs_f32,
        lane_average: r.lane_average,
        setup: r.split.setup,
        step: r.split.step,
        slots: r.split.slots,
        triangles: r.split.triangles,
        waves: r.waves,
        rays_per_kclk: r.rays_per_kclk,
        aco_branches: r.aco_branches,
        aco_vs_f32: r.aco_vs_f32,
        aco_triangles: r.aco_triangles,
        branches: &r.branches,
    }))
}

/// The other vendors' section: their compilers' own whole-shader cycle estimates at P = 1 with
/// what each assumes, beside the ray-weighted AMD figures ("" without rows). Whole-shader
/// figures cannot be weighted by the rays: they give no per-block costs.
pub fn vendors_section(rows: &[super::isa::IsaRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut md = String::from(
        "# The other vendors' own estimates (whole shader)\n\nThese compilers print one cycle figure per kernel, not \
         per block, so the rays cannot weigh their loops: each figure is the compiler's own assumption about how \
         often loops run, shown as it is, with ÷ f32 at the same B. Not a measurement.\n\n",
    );
    let mut devices: Vec<String> = Vec::new();
    for r in rows {
        if !devices.contains(&r.device_label()) {
            devices.push(r.device_label());
        }
    }
    for d in devices {
        let g: Vec<&super::isa::IsaRow> = rows.iter().filter(|r| r.device_label() == d && r.packet == 1).collect();
        let Some(first) = g.first() else { continue };
        let assumes = first.vendor.get().map_or("no cycle estimate from this driver", |v| v.cycles);
        md += &format!("## {d}: {assumes}\n\n");
        md += "| kernel | layout | math | B | cycles | ÷ f32 | registers | spills | status |\n|---|---|---|---:|---:|---:|---:|---:|---|\n";
        let num = |x: Option<f64>| x.map_or("–".to_string(), |v| format!("{v:.0}"));
        for r in g {
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                r.kernel,
                r.layout,
                r.math,
                r.branching,
                num(r.cycles),
                r.vs_f32.and_then(|v| v.cycles).map_or("–".into(), |v| format!("{v:.2}")),
                num(r.registers),
                num(r.spills),
                r.status
            );
        }
        md += "\n";
    }
    md
}

/// `estimate-rays.json` and `estimate-rays.csv` into `out`.
pub fn write(rows: &[RayRow], out: &Path) -> anyhow::Result<()> {
    crate::fsx::write_atomic(&out.join("estimate-rays.json"), serde_json::to_string_pretty(rows)?.as_bytes())?;
    crate::fsx::write_atomic(&out.join("estimate-rays.csv"), &csv(rows)?)
}

/// The rows of `dir/estimate-rays.json`, `None` where there is none.
pub fn read(dir: &Path) -> anyhow::Result<Option<Vec<RayRow>>> {
    let p = dir.join("estimate-rays.json");
    if !p.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    let rows: Vec<RayRow> = serde_json::from_str(&text)
        .with_context(|| format!("{}: not the rows `halftrace estimate` writes", p.display()))?;
    Ok(Some(rows.into_iter().map(RayRow::typed).collect()))
}

/// `estimate.png` (and `.svg`): one panel per family, scene and ray kind; x = B, one line per
/// layout and math (single rays); y = estimated cycles per ray.
pub fn plot(rows: &[RayRow], out: &Path) -> anyhow::Result<()> {
    let mut panels: Vec<(String, plots::Lines)> = Vec::new();
    for r in rows.iter().filter(|r| r.status.is_ok() && r.packet <= 1) {
        let caption = format!("{} ({}), {} {}", r.family, r.generation, r.scene, r.rays);
        let label = format!("{} {}", r.layout, r.math);
        if !panels.iter().any(|p| p.0 == caption) {
            panels.push((caption.clone(), Vec::new()));
        }
        let lines = &mut panels.iter_mut().find(|p| p.0 == caption).expect("just added").1;
        match lines.iter_mut().find(|l| l.0 == label) {
            Some(l) => l.1.push((r.branching, r.cycles_per_ray)),
            None => lines.push((label, vec![(r.branching, r.cycles_per_ray)])),
        }
    }
    if panels.is_empty() {
        return Ok(());
    }
    plots::panels(
        out,
        "estimate",
        "Estimated cycles per ray (ACO's model weighted by the rays' loop trips, lockstep waves; not a measurement)",
        "branching factor B",
        "cycles per ray",
        &panels,
    )
}
