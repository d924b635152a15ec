//! Sweep results: one [`Row`] per variant, written as CSV and JSON as they come, and the
//! human-readable report (Markdown tables, plots, images) rendered from one or more result
//! folders.

use crate::layout::LayoutId;
use anyhow::Context;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One variant's results, with everything needed to read it alone months later.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Row {
    pub scene: String,
    pub triangles: usize,
    pub rays: String,
    pub ray_count: usize,
    pub layout: String,
    /// f16h math mode (f16, f32, mixed); `f32` for the f32 layout, `n/a` for rq.
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    /// Float-control modes of the kernel: `on`, `off` (a build exact without them), `n/a`.
    #[serde(default)]
    pub float_controls: String,
    pub kernel: String,
    pub device: String,
    pub driver: String,
    pub version: String,
    pub commit: String,
    /// `ok`, or `FAILED: …` when the variant disagreed with its CPU reference.
    pub status: String,
    pub mrays_median: f64,
    pub mrays_min: f64,
    pub mrays_max: f64,
    pub ms_median: f64,
    pub ms_min: f64,
    pub ms_max: f64,
    pub timed_dispatches: usize,
    pub nodes_per_ray: f64,
    pub box_tests_per_ray: f64,
    pub tri_tests_per_ray: f64,
    pub reanchors_per_ray: f64,
    pub packet_nodes_per_packet: f64,
    pub simd_utilisation: f64,
    /// Node bytes of our BVH; for `rq`, the driver's acceleration-structure bytes.
    pub bvh_bytes: u64,
    /// BVH build (binary SAH + collapse + encode) or, for `rq`, the driver's build, ms.
    pub build_ms: f64,
    pub bytes_per_node: u64,
    pub triangle_bytes: u64,
    pub stack_bytes_per_ray: u64,
    /// Bytes of node data fetched per ray: nodes visited × node bytes.
    pub node_bytes_per_ray: f64,
    pub differs_from_f32: usize,
    pub false_misses: usize,
    pub max_abs_dt: f64,
    /// The device's raw fp16:fp32 arithmetic throughput ratio (`devices --bench`, geometric
    /// mean over sub, mul, min, max, compare), measured once per sweep.
    pub device_fp16_ratio: f64,
}

/// Keeps `results.csv` and `results.json` current: after each row both are rewritten through a
/// temporary file and a rename ([`crate::fsx`]), so an interrupted sweep keeps every finished
/// row and no write ever leaves a truncated file.
pub struct Writer {
    dir: PathBuf,
    rows: Vec<Row>,
}

impl Writer {
    /// A writer into `dir` that starts from `rows` (the rows a resumed sweep keeps). Nothing is
    /// written until the first [`Writer::push`].
    pub fn create(dir: &Path, rows: Vec<Row>) -> anyhow::Result<Writer> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Writer { dir: dir.into(), rows })
    }

    pub fn push(&mut self, row: Row) -> anyhow::Result<()> {
        self.rows.push(row);
        write_rows(&self.dir, &self.rows)
    }

    pub fn rows(&self) -> &[Row] {
        &self.rows
    }
}

/// Whether rows of `layout` have work counters (unknown layouts, e.g. from another version,
/// are assumed to).
fn has_counters(layout: &str) -> bool {
    LayoutId::parse(layout).map(|l| l.caps().counters).unwrap_or(true)
}

/// The BVH layouts that have rows, in registry order.
fn layouts_in(rows: &[&Row]) -> Vec<&'static str> {
    LayoutId::layouts().map(|l| l.name()).filter(|n| rows.iter().any(|r| r.layout == *n)).collect()
}

/// The files a sweep writes into its folder (besides per-layout images, [`is_output`]).
pub const OUTPUTS: &[&str] = &["results.csv", "results.json", "report.md", "device_bench.json", "render.png"];
const PLOTS: &[&str] = &["ratio_vs_b", "ratio_vs_p", "mrays", "memory", "schemes"];

/// Whether a file name is one a sweep writes (so `--force` may replace it).
pub fn is_output(name: &str) -> bool {
    OUTPUTS.contains(&name)
        || PLOTS.iter().any(|p| name == format!("{p}.png") || name == format!("{p}.svg"))
        || is_image(name)
}

/// Whether a file name is one of the images a sweep renders from its traces (the shaded
/// render, per-layout heat maps and diff masks), not from its rows.
pub fn is_image(name: &str) -> bool {
    name == "render.png"
        || (name.starts_with("heat_") && name.ends_with(".png"))
        || (name.starts_with("diff_") && name.ends_with("_vs_f32.png"))
}

/// Rows in the report's order, whatever order they were run or merged in: by device, scene,
/// rays, layout (registry order), math, B, P, float controls and kernel. A sweep split into
/// shards and merged reports exactly as the unsplit sweep.
pub fn sorted(rows: &[Row]) -> Vec<Row> {
    let mut v = rows.to_vec();
    let layout = |r: &Row| LayoutId::all().position(|l| l.name() == r.layout).unwrap_or(usize::MAX);
    v.sort_by(|a, b| {
        (
            &a.device,
            &a.driver,
            &a.scene,
            &a.rays,
            layout(a),
            &a.layout,
            &a.math,
            a.branching,
            a.packet,
            &a.float_controls,
            &a.kernel,
        )
            .cmp(&(
                &b.device,
                &b.driver,
                &b.scene,
                &b.rays,
                layout(b),
                &b.layout,
                &b.math,
                b.branching,
                b.packet,
                &b.float_controls,
                &b.kernel,
            ))
    });
    v
}

/// Writes `results.csv` and `results.json` of `rows` into `dir` (atomically each).
pub fn write_rows(dir: &Path, rows: &[Row]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut csv = csv::Writer::from_writer(Vec::new());
    for r in rows {
        csv.serialize(r)?;
    }
    let bytes = csv.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::fsx::write_atomic(&dir.join("results.csv"), &bytes)?;
    crate::fsx::write_atomic(&dir.join("results.json"), serde_json::to_string_pretty(rows)?.as_bytes())
}

/// Reads the rows of `DIR/results.csv`.
pub fn read_rows(dir: &Path) -> anyhow::Result<Vec<Row>> {
    let p = dir.join("results.csv");
    let mut r = csv::Reader::from_path(&p).with_context(|| format!("reading {}", p.display()))?;
    r.deserialize().enumerate().map(|(i, x)| x.with_context(|| format!("{}: row {}", p.display(), i + 2))).collect()
}

/// f16h ÷ f32 ratios of one (device, scene, rays, B, P) pair of rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Ratio {
    pub device: String,
    pub scene: String,
    pub rays: String,
    pub branching: usize,
    pub packet: usize,
    /// Time ratio (median ms), >1 means f16h is slower.
    pub time: f64,
    pub nodes: f64,
    pub box_tests: f64,
    pub tri_tests: f64,
    pub bytes: f64,
}

/// Pairs f16h rows in the seed's fp16 math with the f32 row of the same device, scene, rays,
/// B and P.
pub fn ratios(rows: &[Row]) -> Vec<Ratio> {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status == "ok").collect();
    let mut out = Vec::new();
    for h in ok.iter().filter(|r| r.layout == "f16h" && r.math == "f16") {
        if let Some(f) = ok.iter().find(|f| {
            f.layout == "f32"
                && f.device == h.device
                && f.scene == h.scene
                && f.rays == h.rays
                && f.branching == h.branching
                && f.packet == h.packet
        }) {
            let div = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
            out.push(Ratio {
                device: h.device.clone(),
                scene: h.scene.clone(),
                rays: h.rays.clone(),
                branching: h.branching,
                packet: h.packet,
                time: div(h.ms_median, f.ms_median),
                nodes: div(h.nodes_per_ray, f.nodes_per_ray),
                box_tests: div(h.box_tests_per_ray, f.box_tests_per_ray),
                tri_tests: div(h.tri_tests_per_ray, f.tri_tests_per_ray),
                bytes: div(h.bvh_bytes as f64, f.bvh_bytes as f64),
            });
        }
    }
    out
}

/// The storage vs arithmetic table: per (device, B, P), Mrays/s of f16h in each math mode ÷
/// Mrays/s of f32 (means over scenes and rays), node bytes fetched per ray, and the device's
/// raw fp16:fp32 ratio.
fn separated_effects(rows: &[Row]) -> String {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status == "ok").collect();
    let mut acc: BTreeMap<(String, usize, usize), BTreeMap<String, (f64, usize)>> = BTreeMap::new();
    let mut bytes: BTreeMap<(String, usize, usize, String), (f64, usize)> = BTreeMap::new();
    let mut raw: BTreeMap<String, f64> = BTreeMap::new();
    for h in ok.iter().filter(|r| r.layout == "f16h") {
        if let Some(f) = ok.iter().find(|f| {
            f.layout == "f32"
                && f.device == h.device
                && f.scene == h.scene
                && f.rays == h.rays
                && f.branching == h.branching
                && f.packet == h.packet
        }) {
            let e = acc
                .entry((h.device.clone(), h.branching, h.packet))
                .or_default()
                .entry(h.math.clone())
                .or_insert((0.0, 0));
            e.0 += h.mrays_median / f.mrays_median;
            e.1 += 1;
            for r in [h, f] {
                let k = (
                    r.device.clone(),
                    r.branching,
                    r.packet,
                    if r.layout == "f32" { "f32".to_string() } else { format!("f16h/{}", r.math) },
                );
                let b = bytes.entry(k).or_insert((0.0, 0));
                b.0 += r.node_bytes_per_ray;
                b.1 += 1;
            }
        }
        raw.insert(h.device.clone(), h.device_fp16_ratio);
    }
    if acc.is_empty() {
        return String::new();
    }
    let mut md = String::from("## Storage vs arithmetic: f16h math modes ÷ f32 (Mrays/s)\n\nf16 = the seed (fp16 box tests and origin moves); f32 = the same fp16 nodes widened on load, fp32 arithmetic; mixed = fp16 differences and products, fp32 min/max/compare. Above 1: faster than f32. Node bytes per ray = nodes visited × node bytes. Raw fp16:fp32 = the device's own arithmetic ratio (`halftrace devices --bench`).\n\n| device | B | P | f16 ÷ f32 | f32 ÷ f32 | mixed ÷ f32 | node bytes/ray f32 | f16h/f16 | f16h/f32 | raw fp16:fp32 |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for ((d, b, p), m) in &acc {
        let get = |k: &str| m.get(k).map(|(s, n)| fmt(s / *n as f64)).unwrap_or_else(|| "–".into());
        let by = |k: &str| {
            bytes
                .get(&(d.clone(), *b, *p, k.to_string()))
                .map(|(s, n)| format!("{:.0}", s / *n as f64))
                .unwrap_or_else(|| "–".into())
        };
        md += &format!(
            "| {d} | {b} | {p} | {} | {} | {} | {} | {} | {} | {} |\n",
            get("f16"),
            get("f32"),
            get("mixed"),
            by("f32"),
            by("f16h/f16"),
            by("f16h/f32"),
            fmt(raw[d])
        );
    }
    md + "\n"
}

/// One (device, layout/math label, B) point of the schemes table.
#[derive(Clone, Debug, Default)]
struct SchemePoint {
    n: usize,
    /// Sums of the per-(scene, rays) ratios to f32: Mrays/s, BVH bytes, nodes, box tests,
    /// triangle tests.
    ratio: [f64; 5],
    node_bytes_per_ray: f64,
    stack_bytes: u64,
    differs: usize,
    false_misses: usize,
    max_dt: f64,
}

/// A row's scheme label: the layout, its math mode where it has several, `fc off` builds marked.
fn scheme_label(r: &Row) -> String {
    let several = LayoutId::parse(&r.layout).map(|l| l.caps().maths.len() > 1).unwrap_or(true);
    let mut s = if several { format!("{}/{}", r.layout, r.math) } else { r.layout.clone() };
    if r.float_controls == "off" {
        s += " (fc off)";
    }
    s
}

/// Every BVH layout and math mode at each B (P = 1) against f32 at the same B, per device:
/// (device, registry order, label, B) → point.
fn scheme_points(rows: &[Row]) -> BTreeMap<(String, usize, String, usize), SchemePoint> {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status == "ok" && r.packet == 1 && has_counters(&r.layout)).collect();
    let order = |l: &str| LayoutId::layouts().position(|x| x.name() == l).unwrap_or(usize::MAX);
    let mut acc: BTreeMap<(String, usize, String, usize), SchemePoint> = BTreeMap::new();
    for h in ok.iter().filter(|r| LayoutId::parse(&r.layout).is_ok_and(|l| l.bvh().is_some()) && !r.kernel.is_empty()) {
        let Some(f) = ok.iter().find(|f| {
            f.layout == "f32"
                && f.float_controls == h.float_controls
                && f.device == h.device
                && f.scene == h.scene
                && f.rays == h.rays
                && f.branching == h.branching
        }) else {
            continue;
        };
        let div = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
        let e = acc.entry((h.device.clone(), order(&h.layout), scheme_label(h), h.branching)).or_default();
        e.n += 1;
        for (i, v) in [
            div(h.mrays_median, f.mrays_median),
            div(h.bvh_bytes as f64, f.bvh_bytes as f64),
            div(h.nodes_per_ray, f.nodes_per_ray),
            div(h.box_tests_per_ray, f.box_tests_per_ray),
            div(h.tri_tests_per_ray, f.tri_tests_per_ray),
        ]
        .into_iter()
        .enumerate()
        {
            e.ratio[i] += v;
        }
        e.node_bytes_per_ray += h.node_bytes_per_ray;
        e.stack_bytes = e.stack_bytes.max(h.stack_bytes_per_ray);
        e.differs += h.differs_from_f32;
        e.false_misses += h.false_misses;
        e.max_dt = e.max_dt.max(h.max_abs_dt);
    }
    acc
}

/// The schemes table: which reduced-precision scheme, at which B, on this device.
fn schemes_table(points: &BTreeMap<(String, usize, String, usize), SchemePoint>) -> String {
    if points.is_empty() {
        return String::new();
    }
    let mut md = String::from("## Schemes: every layout and math mode ÷ f32, per B (P = 1)\n\nMeans over scenes and ray kinds of each variant's ratio to `f32` at the same B (user kernels excluded). Mrays/s above 1: faster than f32; BVH bytes, nodes, box and triangle tests below 1: smaller / less work. Node bytes/ray = nodes visited × node bytes; stack bytes = the kernel's per-ray stack. ≠ f32, false misses: rays summed over scenes and ray kinds (0 for every conservative layout; `f16h-seed` is the poster's algorithm without an error bound); max |Δt| over them.\n\n| device | scheme | B | Mrays/s ÷ f32 | BVH bytes ÷ f32 | node bytes/ray | nodes ÷ f32 | box tests ÷ f32 | tri tests ÷ f32 | stack bytes/ray | ≠ f32 | false misses | max abs Δt |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for ((d, _, label, b), p) in points {
        let m = |v: f64| fmt(v / p.n as f64);
        md += &format!(
            "| {d} | {label} | {b} | {} | {} | {:.0} | {} | {} | {} | {} | {} | {} | {:.3e} |\n",
            m(p.ratio[0]),
            m(p.ratio[1]),
            p.node_bytes_per_ray / p.n as f64,
            m(p.ratio[2]),
            m(p.ratio[3]),
            m(p.ratio[4]),
            p.stack_bytes,
            p.differs,
            p.false_misses,
            p.max_dt
        );
    }
    md + "\n![schemes](schemes.png)\n\n"
}

/// Mean of the ratios of each series point: (device, key) → (time, nodes, box, tri, bytes).
fn series(r: &[Ratio], by_b: bool) -> BTreeMap<(String, usize), [f64; 5]> {
    let mut acc: BTreeMap<(String, usize), ([f64; 5], usize)> = BTreeMap::new();
    for x in r.iter().filter(|x| if by_b { x.packet == 1 } else { x.branching == 4 }) {
        let k = (x.device.clone(), if by_b { x.branching } else { x.packet });
        let e = acc.entry(k).or_insert(([0.0; 5], 0));
        for (i, v) in [x.time, x.nodes, x.box_tests, x.tri_tests, x.bytes].into_iter().enumerate() {
            e.0[i] += v;
        }
        e.1 += 1;
    }
    acc.into_iter().map(|(k, (s, n))| (k, s.map(|v| v / n as f64))).collect()
}

fn fmt(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "–".into()
    }
}

/// Renders `report.md` and the plots into `out` from `rows` (from one or more folders).
pub fn render(rows: &[Row], out: &Path, sources: &[PathBuf]) -> anyhow::Result<()> {
    std::fs::create_dir_all(out)?;
    let rows = &sorted(rows);
    let r = ratios(rows);
    let by_b = series(&r, true);
    let by_p = series(&r, false);
    let mut md = String::new();
    md += "# halftrace sweep report\n\n";
    md += &format!(
        "Rendered from {} result row(s) in: {}.\n\n",
        rows.len(),
        sources.iter().map(|p| format!("`{}`", p.display())).collect::<Vec<_>>().join(", ")
    );
    let mut devices: Vec<(String, String)> = rows.iter().map(|r| (r.device.clone(), r.driver.clone())).collect();
    devices.sort();
    devices.dedup();
    for (d, drv) in &devices {
        md += &format!("- device **{d}**, driver {drv}\n");
    }
    let mut versions: Vec<String> = rows.iter().map(|r| format!("{} ({})", r.version, r.commit)).collect();
    versions.sort();
    versions.dedup();
    md += &format!("- halftrace {}\n", versions.join(", "));
    let failed: Vec<&Row> = rows.iter().filter(|r| r.status.starts_with("FAILED")).collect();
    let skipped: Vec<&Row> = rows.iter().filter(|r| r.status.starts_with("skipped")).collect();
    md += &format!(
        "- variants: {} ok, {} failed validation, {} skipped\n\n",
        rows.len() - failed.len() - skipped.len(),
        failed.len(),
        skipped.len()
    );
    for f in &failed {
        md += &format!("**FAILED**: {} {} {}: {}\n\n", f.scene, f.rays, f.kernel, f.status);
    }
    let mut skip_lines: Vec<String> = skipped
        .iter()
        .map(|f| format!("{} on {}: {}", f.kernel, f.device, f.status.trim_start_matches("skipped: ")))
        .collect();
    skip_lines.dedup();
    for l in skip_lines {
        md += &format!("Skipped: {l}\n\n");
    }

    md += "## Headline: f16h ÷ f32 (the seed's \"average differences to regular single-precision traversal\")\n\n";
    md += "Means over scenes and ray kinds of the per-variant ratios; time is the median GPU time, work the per-ray counters, bytes the node arrays. Below 1: f16h is faster / does less / is smaller.\n\n";
    md += "### By branching factor (single rays, P = 1)\n\n| device | B | time | nodes visited | box tests | triangle tests | node bytes |\n|---|---:|---:|---:|---:|---:|---:|\n";
    for ((d, b), v) in &by_b {
        md +=
            &format!("| {d} | {b} | {} | {} | {} | {} | {} |\n", fmt(v[0]), fmt(v[1]), fmt(v[2]), fmt(v[3]), fmt(v[4]));
    }
    md += "\n### By packet size (MBVH4, B = 4)\n\n| device | P | time | nodes visited | box tests | triangle tests | node bytes |\n|---|---:|---:|---:|---:|---:|---:|\n";
    for ((d, p), v) in &by_p {
        md +=
            &format!("| {d} | {p} | {} | {} | {} | {} | {} |\n", fmt(v[0]), fmt(v[1]), fmt(v[2]), fmt(v[3]), fmt(v[4]));
    }
    md += "\n![ratio vs B](ratio_vs_b.png) ![ratio vs P](ratio_vs_p.png)\n\n";
    md += &separated_effects(rows);
    let scheme_pts = scheme_points(rows);
    md += &schemes_table(&scheme_pts);
    for b in LayoutId::all().filter(|l| l.baseline().is_some()) {
        let base: Vec<&Row> = rows.iter().filter(|r| r.layout == b.name() && r.status == "ok").collect();
        if base.is_empty() {
            continue;
        }
        md += &format!("## Against `{b}` on the same device\n\n`{b}`: {}. Mrays/s of each variant ÷ Mrays/s of `{b}` for the same scene and rays (above 1: faster). Its structures' size and build time are in its row.\n\n| device | scene | rays | kernel | Mrays/s | ÷ {b} |\n|---|---|---|---|---:|---:|\n", b.summary());
        for x in rows.iter().filter(|r| r.status == "ok") {
            if let Some(q) = base.iter().find(|q| q.device == x.device && q.scene == x.scene && q.rays == x.rays) {
                md += &format!(
                    "| {} | {} | {} | {} | {:.2} | {:.3} |\n",
                    x.device,
                    x.scene,
                    x.rays,
                    x.kernel,
                    x.mrays_median,
                    x.mrays_median / q.mrays_median
                );
            }
        }
        md += "\n";
    }
    md += "## Every variant\n\nFloat controls `on`: the kernel declares round-to-nearest-even and inf/NaN preservation and matches its CPU reference bit for bit; `off`: a build whose hits stay exact without them (used on devices that lack them, or forced with `--float-controls off`). For baselines (`rq`), B, P and the work counters do not apply, and for user kernels that do not count, the work counters are not measured (both shown as –); a baseline's bytes are its own acceleration structures. ≠ f32 counts rays that hit where f32 misses or the reverse, or hit another triangle at a t more than 1e-5 (relative) away.\n\n| device | scene | rays | kernel | float controls | Mrays/s median (min–max) | ms | nodes/ray | box/ray | tri/ray | re-anchors/ray | SIMD util. | BVH bytes | build ms | B/node | stack B/ray | ≠ f32 | false misses | max abs Δt | status |\n|---|---|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
    for x in rows {
        let na = !has_counters(&x.layout) || x.nodes_per_ray.is_nan();
        let c = |v: String| if na { "–".to_string() } else { v };
        md += &format!(
            "| {} | {} ({} tris) | {} ({}) | {} | {} | {:.2} ({:.2}–{:.2}) | {:.3} | {} | {} | {} | {} | {} | {} | {:.2} | {} | {} | {} | {} | {:.3e} | {} |\n",
            x.device, x.scene, x.triangles, x.rays, x.ray_count, x.kernel, if x.float_controls.is_empty() { "n/a" } else { &x.float_controls }, x.mrays_median, x.mrays_min, x.mrays_max, x.ms_median,
            c(format!("{:.2}", x.nodes_per_ray)), c(format!("{:.2}", x.box_tests_per_ray)), c(format!("{:.2}", x.tri_tests_per_ray)), c(format!("{:.3}", x.reanchors_per_ray)),
            c(format!("{:.1}%", 100.0 * x.simd_utilisation)), x.bvh_bytes, x.build_ms, c(x.bytes_per_node.to_string()), c(x.stack_bytes_per_ray.to_string()),
            x.differs_from_f32, x.false_misses, x.max_abs_dt, x.status
        );
    }
    md += "\n![Mrays/s per variant](mrays.png) ![memory per layout and B](memory.png)\n";
    let mut imgs = vec!["render.png".to_string()];
    for l in LayoutId::layouts() {
        imgs.push(format!("heat_{l}.png"));
    }
    for l in LayoutId::layouts().filter(|&l| l != LayoutId::f32()) {
        imgs.push(format!("diff_{l}_vs_f32.png"));
    }
    imgs.retain(|f| out.join(f).exists());
    if !imgs.is_empty() {
        md += "\n## Images\n\nShaded primary render (f32 hits); nodes visited per pixel of each layout (B = 4, P = 1, default math; one colour scale); pixels whose hit differs from f32 (white), black when none does.\n\n";
        for i in imgs {
            md += &format!("![{i}]({i}) ");
        }
        md += "\n";
    }
    crate::fsx::write_atomic(&out.join("report.md"), md.as_bytes())?;
    plots(rows, &by_b, &by_p, out)?;
    scheme_plot(&scheme_pts, out)
}

/// Mrays/s ÷ f32 against B, one line per (device,) scheme.
fn scheme_plot(points: &BTreeMap<(String, usize, String, usize), SchemePoint>, out: &Path) -> anyhow::Result<()> {
    let devices: std::collections::BTreeSet<&String> = points.keys().map(|k| &k.0).collect();
    let mut lines: Vec<(String, Vec<(usize, f64)>)> = Vec::new();
    for ((d, _, label, b), p) in points {
        let name = if devices.len() > 1 { format!("{label} ({d})") } else { label.clone() };
        match lines.iter_mut().find(|l| l.0 == name) {
            Some(l) => l.1.push((*b, p.ratio[0] / p.n as f64)),
            None => lines.push((name, vec![(*b, p.ratio[0] / p.n as f64)])),
        }
    }
    line_chart(
        out,
        "schemes",
        "Mrays/s of each scheme / f32 by branching factor (P = 1)",
        "branching factor B",
        "Mrays/s / f32",
        &lines,
    )
}

fn font() -> anyhow::Result<()> {
    use std::sync::OnceLock;
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let candidates = [
            "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
            "/usr/share/fonts/TTF/DejaVuSans.ttf",
            "/usr/share/fonts/dejavu/DejaVuSans.ttf",
        ];
        for c in candidates {
            if let Ok(b) = std::fs::read(c) {
                let leaked: &'static [u8] = Box::leak(b.into_boxed_slice());
                return plotters::style::register_font("sans-serif", FontStyle::Normal, leaked)
                    .map_err(|_| format!("{c}: not a usable font"));
            }
        }
        Err("no DejaVuSans.ttf found for plot labels (install fonts-dejavu-core: scripts/install-deps.sh)".into())
    })
    .clone()
    .map_err(anyhow::Error::msg)
}

type Series = BTreeMap<(String, usize), [f64; 5]>;

/// Draws a line chart of named series on both a PNG and an SVG.
/// One line of a chart: its points and, for time plots, min–max bars over the timed dispatches.
#[derive(Clone, Debug, Default)]
struct Line {
    label: String,
    pts: Vec<(usize, f64)>,
    bars: Vec<(usize, f64, f64)>,
}

/// One panel: its own x axis (one series, e.g. by B or by P) and lines.
struct Panel {
    caption: String,
    xlabel: String,
    lines: Vec<Line>,
}

const COLOURS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
];

/// The colour and marker shape of a label: fixed by its position among every label of the
/// chart, so a layout/math keeps its look in every panel.
fn look(label: &str, labels: &[String]) -> (RGBColor, usize) {
    let i = labels.iter().position(|l| l == label).unwrap_or(0);
    (COLOURS[i % COLOURS.len()], (i / COLOURS.len() + i) % 4)
}

/// Draws panels side by side (PNG and SVG): log2 x axes with a tick at every tested value,
/// one colour and marker per label, min–max bars where a line has them. An empty panel still
/// gets a finite axis (an infinite one makes the mesh drawing loop forever).
fn chart(out: &Path, name: &str, title: &str, ylabel: &str, panels: &[Panel]) -> anyhow::Result<()> {
    font()?;
    let mut labels: Vec<String> = Vec::new();
    for l in panels.iter().flat_map(|p| p.lines.iter()) {
        if !labels.contains(&l.label) {
            labels.push(l.label.clone());
        }
    }
    let width = 520 * panels.len().max(1) as u32 + 80;
    macro_rules! draw {
        ($root:expr) => {{
            let root = $root;
            root.fill(&WHITE)?;
            let root = root.titled(title, ("sans-serif", 22))?;
            let areas = root.split_evenly((1, panels.len().max(1)));
            for (panel, area) in panels.iter().zip(areas.iter()) {
                let mut xs: Vec<usize> = panel.lines.iter().flat_map(|l| l.pts.iter().map(|p| p.0)).collect();
                xs.sort();
                xs.dedup();
                // x in thousandths of log2 (integer coordinates carry exact key points).
                let lx = |x: usize| ((x as f64).log2() * 1000.0).round() as i32;
                let keys: Vec<i32> = xs.iter().map(|&x| lx(x)).collect();
                let (xmin, xmax) = match (keys.first(), keys.last()) {
                    (Some(&a), Some(&b)) if a < b => (a, b),
                    (Some(&a), _) => (a - 1000, a + 1000),
                    _ => (0, 1000),
                };
                let ymax = panel
                    .lines
                    .iter()
                    .flat_map(|l| l.pts.iter().map(|p| p.1).chain(l.bars.iter().map(|b| b.2)))
                    .filter(|y| y.is_finite())
                    .fold(0.0f64, f64::max)
                    .max(1e-9)
                    * 1.12;
                let caption =
                    if xs.is_empty() { format!("{} (no data)", panel.caption) } else { panel.caption.clone() };
                let mut ch = ChartBuilder::on(area)
                    .caption(caption, ("sans-serif", 16))
                    .margin(10)
                    .x_label_area_size(36)
                    .y_label_area_size(56)
                    .build_cartesian_2d(((xmin - 350)..(xmax + 350)).with_key_points(keys.clone()), 0.0..ymax)?;
                ch.configure_mesh()
                    .x_desc(panel.xlabel.as_str())
                    .y_desc(ylabel)
                    .x_label_formatter(&|v| format!("{}", 2f64.powf(*v as f64 / 1000.0).round()))
                    .draw()?;
                for line in &panel.lines {
                    let (c, m) = look(&line.label, &labels);
                    let pts: Vec<(i32, f64)> =
                        line.pts.iter().filter(|p| p.1.is_finite()).map(|&(x, y)| (lx(x), y)).collect();
                    for &(x, lo, hi) in line.bars.iter().filter(|b| b.1.is_finite() && b.2.is_finite()) {
                        let xm = lx(x);
                        let y = pts.iter().find(|p| p.0 == xm).map(|p| p.1).unwrap_or((lo + hi) / 2.0);
                        ch.draw_series(std::iter::once(ErrorBar::new_vertical(xm, lo, y, hi, c.stroke_width(1), 8)))?;
                    }
                    let lg = move |(x, y): (i32, i32)| {
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(0, 0), (18, 0)], c.stroke_width(2))
                            + Circle::new((9, 0), 3, c.filled())
                    };
                    ch.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
                        .label(line.label.clone())
                        .legend(lg);
                    match m {
                        0 => {
                            ch.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
                        }
                        1 => {
                            ch.draw_series(pts.iter().map(|&p| TriangleMarker::new(p, 5, c.filled())))?;
                        }
                        2 => {
                            ch.draw_series(pts.iter().map(|&p| Cross::new(p, 5, c.stroke_width(2))))?;
                        }
                        _ => {
                            ch.draw_series(
                                pts.iter()
                                    .map(|&p| EmptyElement::at(p) + Rectangle::new([(-4, -4), (4, 4)], c.filled())),
                            )?;
                        }
                    }
                }
                if panel.lines.iter().any(|l| !l.pts.is_empty()) {
                    ch.configure_series_labels()
                        .background_style(WHITE.mix(0.85))
                        .border_style(BLACK)
                        .label_font(("sans-serif", 12))
                        .position(SeriesLabelPosition::UpperRight)
                        .draw()?;
                }
            }
            root.present()?;
        }};
    }
    crate::fsx::with_temp(&out.join(format!("{name}.png")), |png| {
        draw!(BitMapBackend::new(png, (width, 520)).into_drawing_area());
        Ok(())
    })?;
    crate::fsx::with_temp(&out.join(format!("{name}.svg")), |svg| {
        draw!(SVGBackend::new(svg, (width, 520)).into_drawing_area());
        Ok(())
    })
}

/// One panel of plain lines.
fn line_chart(
    out: &Path,
    name: &str,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    lines: &[(String, Vec<(usize, f64)>)],
) -> anyhow::Result<()> {
    let panel = Panel {
        caption: String::new(),
        xlabel: xlabel.into(),
        lines: lines.iter().map(|(l, p)| Line { label: l.clone(), pts: p.clone(), bars: Vec::new() }).collect(),
    };
    chart(out, name, title, ylabel, &[panel])
}

fn ratio_lines(s: &Series) -> Vec<(String, Vec<(usize, f64)>)> {
    let mut devices: Vec<String> = s.keys().map(|k| k.0.clone()).collect();
    devices.dedup();
    let mut lines = Vec::new();
    for d in &devices {
        for (i, what) in [(0, "time"), (2, "box tests"), (1, "nodes visited")] {
            let pts = s.iter().filter(|(k, _)| &k.0 == d).map(|(k, v)| (k.1, v[i])).collect();
            let label = if devices.len() > 1 { format!("{what} ({d})") } else { what.to_string() };
            lines.push((label, pts));
        }
    }
    lines
}

fn plots(rows: &[Row], by_b: &Series, by_p: &Series, out: &Path) -> anyhow::Result<()> {
    line_chart(
        out,
        "ratio_vs_b",
        "f16h / f32 by branching factor (P = 1)",
        "branching factor B",
        "f16h / f32",
        &ratio_lines(by_b),
    )?;
    line_chart(
        out,
        "ratio_vs_p",
        "f16h / f32 by packet size (B = 4)",
        "packet size P",
        "f16h / f32",
        &ratio_lines(by_p),
    )?;
    // Mrays/s per variant: one panel per series (by B at P = 1, by P at the packet B), one
    // line per layout/math (mean over scenes and ray kinds), min–max bars over the timed
    // dispatches (means of the per-row minima and maxima).
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status == "ok").collect();
    let pb = ok.iter().filter(|r| r.packet > 1).map(|r| r.branching).next().unwrap_or(4);
    let mut by_b_lines = Vec::new();
    let mut by_p_lines = Vec::new();
    let mut labels: Vec<String> = Vec::new();
    for r in ok.iter().filter(|r| has_counters(&r.layout) && r.kernel.starts_with("trav_")) {
        let l = scheme_label(r);
        if !labels.contains(&l) {
            labels.push(l);
        }
    }
    for label in &labels {
        let mean = |f: &dyn Fn(&Row) -> bool, key: &dyn Fn(&Row) -> usize| -> Line {
            let mut m: BTreeMap<usize, ([f64; 3], usize)> = BTreeMap::new();
            for r in ok.iter().filter(|r| scheme_label(r) == *label && r.kernel.starts_with("trav_") && f(r)) {
                let e = m.entry(key(r)).or_insert(([0.0; 3], 0));
                e.0[0] += r.mrays_median;
                e.0[1] += r.mrays_min;
                e.0[2] += r.mrays_max;
                e.1 += 1;
            }
            Line {
                label: label.clone(),
                pts: m.iter().map(|(k, (s, n))| (*k, s[0] / *n as f64)).collect(),
                bars: m.iter().map(|(k, (s, n))| (*k, s[1] / *n as f64, s[2] / *n as f64)).collect(),
            }
        };
        by_b_lines.push(mean(&|r: &Row| r.packet == 1, &|r: &Row| r.branching));
        let p = mean(&|r: &Row| r.branching == pb, &|r: &Row| r.packet);
        if p.pts.len() > 1 {
            by_p_lines.push(p);
        }
    }
    let mut panels = vec![Panel {
        caption: "by branching factor (P = 1)".into(),
        xlabel: "branching factor B".into(),
        lines: by_b_lines,
    }];
    if !by_p_lines.is_empty() {
        panels.push(Panel {
            caption: format!("by packet size (B = {pb})"),
            xlabel: "packet size P".into(),
            lines: by_p_lines,
        });
    }
    chart(
        out,
        "mrays",
        "Mrays/s per variant (mean over scenes and ray kinds; bars: min–max over timed dispatches)",
        "Mrays/s",
        &panels,
    )?;
    // Memory per layout and B.
    let mut lines = Vec::new();
    let mut xs = Vec::new();
    for layout in layouts_in(&ok) {
        let mut m: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
        for r in ok.iter().filter(|r| r.layout == layout && r.packet == 1) {
            let e = m.entry(r.branching).or_insert((0.0, 0));
            e.0 += r.bvh_bytes as f64 / 1024.0;
            e.1 += 1;
        }
        let pts: Vec<(usize, f64)> = m.into_iter().map(|(k, (s, n))| (k, s / n as f64)).collect();
        xs.extend(pts.iter().map(|p| p.0));
        lines.push((format!("{layout} node bytes (KiB)"), pts));
    }
    xs.sort();
    xs.dedup();
    let _ = xs;
    line_chart(
        out,
        "memory",
        "BVH node memory per layout and B (mean over scenes)",
        "branching factor B",
        "KiB",
        &lines,
    )
}
