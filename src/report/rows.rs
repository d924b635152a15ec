//! Result rows: one [`Row`] per measured (device, scene, ray set, target), its typed
//! identity ([`RowId`]) and status ([`Status`], from [`crate::base`]), and their storage as `results.csv` and
//! `results.json`, written as they come.

use super::key::What;
pub use crate::base::Status;
use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What makes two rows the same measurement: one spelling for `--resume` (which jobs a
/// folder already records) and `report` (which rows of merged folders collide).
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RowId {
    pub device: String,
    pub driver: String,
    pub scene: String,
    pub rays: String,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    pub float_controls: String,
    pub setup: String,
}

impl std::fmt::Display for RowId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} | {} | {} | {} | {} | {}/{}/B{}/P{} fc {} | setup {}",
            self.device,
            self.driver,
            self.scene,
            self.rays,
            self.kernel,
            self.layout,
            self.math,
            self.branching,
            self.packet,
            self.float_controls,
            if self.setup.is_empty() { "–" } else { &self.setup }
        )
    }
}

/// A row's layout or baseline in report order: the layouts in registry order, then the
/// baselines, then names this version does not know.
pub fn order(name: &str) -> usize {
    let n = LayoutId::all().count();
    match (LayoutId::parse(name), BaselineId::parse(name)) {
        (Ok(l), _) => LayoutId::all().position(|x| x == l).unwrap_or(usize::MAX),
        (_, Some(b)) => n + BaselineId::all().position(|x| x == b).unwrap_or(0),
        _ => usize::MAX,
    }
}

/// One variant's results, with everything needed to read it alone months later.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Row {
    pub scene: String,
    pub triangles: usize,
    pub rays: String,
    pub ray_count: usize,
    pub layout: String,
    /// f16h math mode (f16, f32, mixed); `f32` for the f32 layout, `n/a` for a baseline.
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
    /// A hash of what else decides the row's result: the scene file (its path, size and
    /// modification time), the image size, seed and rays file, a user kernel's source — so
    /// `--resume` runs a job again when any of them changed. Empty in rows of older versions.
    #[serde(default)]
    pub setup: String,
    /// `ok`, `FAILED: …` when the variant disagreed with its CPU reference, or `skipped: …`.
    pub status: Status,
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
    /// Node bytes of our BVH; for `rq` and `rt`, the driver's acceleration-structure bytes.
    pub bvh_bytes: u64,
    /// BVH build (binary SAH + collapse + encode) or, for `rq` and `rt`, the driver's build, ms.
    pub build_ms: f64,
    pub bytes_per_node: u64,
    pub triangle_bytes: u64,
    pub stack_bytes_per_ray: u64,
    /// Bytes of node data fetched per ray: nodes visited × node bytes.
    pub node_bytes_per_ray: f64,
    pub differs_from_f32: usize,
    pub false_misses: usize,
    pub max_abs_dt: f64,
    /// Rays the kernel flagged because fp32 could not decide one of their triangles, re-traced
    /// exactly on the host (their time is in the timings). 0 in rows of older versions.
    #[serde(default)]
    pub flagged_rays: usize,
    /// The device's raw fp16:fp32 arithmetic throughput ratio (`devices --arith`, geometric
    /// mean over sub, mul, min, max, compare), measured once per sweep.
    pub device_fp16_ratio: f64,
    /// What the row measured, typed: set from the kernel where the row is made, parsed once
    /// from the identity columns where a file is read ([`Row::typed`]).
    #[serde(skip)]
    pub what: What,
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

/// Whether rows of `layout` have work counters: every layout's do, a baseline's do not
/// (unknown names, e.g. from another version, are assumed to).
pub fn has_counters(layout: &str) -> bool {
    BaselineId::parse(layout).is_none()
}

/// The layouts that have rows, in registry order.
pub fn layouts_in(rows: &[&Row]) -> Vec<&'static str> {
    LayoutId::all().map(|l| l.name()).filter(|n| rows.iter().any(|r| r.layout == *n)).collect()
}

/// The files a sweep writes into its folder (besides per-layout images, [`is_output`]).
pub const OUTPUTS: &[&str] = &[
    "results.csv",
    "results.json",
    "report.md",
    "headline.md",
    "device_arith.json",
    "device_bench.json",
    "render.png",
    "shard.json",
];
/// The plots (each as `.png` and `.svg`); `schemes` is the old name of `layouts`.
pub const PLOTS: &[&str] = &["ratio_vs_b", "ratio_vs_p", "mrays", "memory", "layouts", "schemes"];

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
    let layout = |r: &Row| order(&r.layout);
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
    crate::fsx::write_atomic(&dir.join("results.csv"), &super::csvx::to_bytes(rows)?)?;
    crate::fsx::write_atomic(&dir.join("results.json"), serde_json::to_string_pretty(rows)?.as_bytes())
}

/// Reads the rows of `DIR/results.csv`. Rows of a renamed layout read under its current name
/// (its kernel names too), so a resume or a merge over older results matches them.
/// Every row is checked: a file of halftrace's columns (a folder, an empty file or another
/// CSV is refused), each value in its domain ([`check_row`]).
pub fn read_rows(dir: &Path) -> anyhow::Result<Vec<Row>> {
    let p = dir.join("results.csv");
    let bytes = crate::fsx::read_regular(&p).with_context(|| format!("reading {}", p.display()))?;
    let mut r = csv::Reader::from_reader(&bytes[..]);
    // (`csv` strips a UTF-8 byte-order mark and reads quoted names, as a spreadsheet saves them.)
    let header: Vec<String> = r.headers().map(|h| h.iter().map(String::from).collect()).unwrap_or_default();
    for need in ["scene", "rays", "layout", "branching", "packet", "kernel", "device", "status", "mrays_median"] {
        anyhow::ensure!(
            header.iter().any(|h| h == need),
            "{}: not a halftrace results.csv (no '{need}' column{})",
            p.display(),
            if bytes.is_empty() { "; the file is empty" } else { "" }
        );
    }
    // Columns added after the first version have defaults (older files load); every other
    // column must be there, named when it is not (rather than serde's "missing field").
    const DEFAULTED: &[&str] = &["float_controls", "setup", "flagged_rays"];
    for c in columns() {
        anyhow::ensure!(
            DEFAULTED.contains(&c.as_str()) || header.contains(&c),
            "{}: the column '{c}' is missing (a halftrace results.csv has {})",
            p.display(),
            columns().join(", ")
        );
    }
    let rows: Vec<Row> = r
        .deserialize()
        .enumerate()
        .map(|(i, x)| {
            let row: Row = x.with_context(|| format!("{}: row {}", p.display(), i + 2))?;
            check_row(&row).map_err(|e| anyhow::anyhow!("{}: row {} ({}): {e}", p.display(), i + 2, row.kernel))?;
            Ok(row)
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(rows.into_iter().map(current_names).map(Row::typed).collect())
}

/// A row's values in their domains: a known layout or baseline, B and P that exist for it,
/// times and speeds finite and non-negative (NaN only where nothing was measured), counts
/// non-negative.
pub fn check_row(r: &Row) -> Result<(), String> {
    // (LayoutId::parse reads former names too, as current_names relies on.)
    if LayoutId::parse(&r.layout).is_ok() {
        if !crate::bvh::BRANCHINGS.contains(&r.branching) {
            return Err(format!("branching {} is not one of {:?}", r.branching, crate::bvh::BRANCHINGS));
        }
        if !crate::variant::PACKETS.contains(&r.packet) {
            return Err(format!("packet {} is not one of {:?}", r.packet, crate::variant::PACKETS));
        }
    } else if BaselineId::parse(&r.layout).is_none() {
        return Err(format!("layout '{}' is neither a layout nor a baseline of this version", r.layout));
    }
    let timed = [
        ("mrays_median", r.mrays_median),
        ("mrays_min", r.mrays_min),
        ("mrays_max", r.mrays_max),
        ("ms_median", r.ms_median),
        ("ms_min", r.ms_min),
        ("ms_max", r.ms_max),
        ("build_ms", r.build_ms),
        ("nodes_per_ray", r.nodes_per_ray),
        ("box_tests_per_ray", r.box_tests_per_ray),
        ("tri_tests_per_ray", r.tri_tests_per_ray),
        ("node_bytes_per_ray", r.node_bytes_per_ray),
    ];
    for (name, v) in timed {
        if v.is_infinite() || v < 0.0 || (v.is_nan() && r.status.is_ok() && name.starts_with("m")) {
            return Err(format!("{name} {v} is not a finite, non-negative number"));
        }
    }
    Ok(())
}

/// A row with its layout's current name (and its built-in kernel's name with it).
fn current_names(mut r: Row) -> Row {
    if let Ok(l) = LayoutId::parse(&r.layout) {
        if l.name() != r.layout {
            let old = format!("trav_{}_", r.layout);
            if let Some(rest) = r.kernel.strip_prefix(&old) {
                r.kernel = format!("trav_{}_{rest}", l.name());
            }
            r.layout = l.name().to_string();
        }
    }
    r
}

/// The column names of a results.csv, read as [`read_rows`] reads them: a UTF-8 byte-order
/// mark and quoted names (`"scene"`, as a spreadsheet re-saves the file) are the names inside.
pub fn header(path: &Path) -> anyhow::Result<Vec<String>> {
    let bytes = crate::fsx::read_regular(path).with_context(|| format!("reading {}", path.display()))?;
    let mut r = csv::Reader::from_reader(&bytes[..]);
    let h = r.headers().with_context(|| format!("{}: reading the header line", path.display()))?;
    Ok(h.iter().map(String::from).collect())
}

/// The columns of `results.csv` this version writes.
pub fn columns() -> Vec<String> {
    super::csvx::header_of(Row::default())
}

super::key::keyed_row!(Row, |r| place: [&r.device, &r.driver, &r.scene, &r.rays], float_controls: &r.float_controls, packet_impl: None);

impl Row {
    /// The row's identity.
    pub fn id(&self) -> RowId {
        RowId {
            device: self.device.clone(),
            driver: self.driver.clone(),
            scene: self.scene.clone(),
            rays: self.rays.clone(),
            kernel: self.kernel.clone(),
            layout: self.layout.clone(),
            math: self.math.clone(),
            branching: self.branching,
            packet: self.packet,
            float_controls: self.float_controls.clone(),
            setup: self.setup.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Results written before a layout was renamed read under its current name, kernel too.
    #[test]
    fn rows_of_a_renamed_layout_read_under_its_current_name() {
        let dir = std::env::temp_dir().join(format!("halftrace-rows-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let row = |layout: &str, kernel: &str| Row {
            layout: layout.into(),
            kernel: kernel.into(),
            branching: 4,
            packet: 1,
            ..Row::default()
        };
        let old = [row("f16h-seed", "trav_f16h-seed_b4_p1"), row("rq", "trav_rq"), row("f16h", "mine")];
        write_rows(&dir, &old).unwrap();
        let got: Vec<(String, String)> = read_rows(&dir).unwrap().into_iter().map(|r| (r.layout, r.kernel)).collect();
        std::fs::remove_dir_all(&dir).unwrap();
        let want = [("f16h-poster", "trav_f16h-poster_b4_p1"), ("rq", "trav_rq"), ("f16h", "mine")];
        assert_eq!(got, want.map(|(l, k)| (l.to_string(), k.to_string())));
    }
}
