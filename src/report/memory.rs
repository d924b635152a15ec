//! The memory side's rows (`halftrace memory` writes them: `memory.csv`, `memory.json`), its
//! report section with one verdict per GPU, and the verdict lines for `headline.md`.

use super::csvx::{display, fixed, opt_display, opt_fixed};
use super::key::{f32_peer, Keyed, What};
use super::rows::Status;
use anyhow::Context as _;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One kernel on one GPU model for one ray set: bytes per ray at each tier.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MemRow {
    pub gpu: String,
    pub scene: String,
    pub triangles: usize,
    pub rays: String,
    pub ray_count: usize,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    /// Lanes in lockstep on the GPU.
    pub wave: usize,
    /// Waves per unit sharing its L1 in the cache model, and where that figure comes from
    /// (`assumed`, or the compiler's occupancy: `memory --compilers`; 0 and empty in files
    /// written before it was recorded).
    #[serde(default)]
    pub resident: usize,
    #[serde(default)]
    pub resident_from: String,
    pub status: Status,
    /// Tier 1, exact: requested bytes per ray.
    pub node_bytes: f64,
    pub vert_bytes: f64,
    pub id_bytes: f64,
    /// The parent-node bytes entering children re-reads (kernels that derive entries then:
    /// `memory::Enter`; 0 elsewhere and in files written before it was modelled).
    #[serde(default)]
    pub enter_bytes: f64,
    /// The bytes the kernel's stack pushes and pops move (`memory::Stack::ops`; packets: two
    /// entries' bytes per child pushed).
    pub stack_bytes: f64,
    /// Tier 2, exact: distinct lines per ray, the ray alone (its packet alone for P > 1).
    pub lines32_alone: f64,
    pub lines64_alone: f64,
    pub lines128_alone: f64,
    /// Distinct lines per ray, the wave's lanes coalesced at each lockstep step.
    pub lines32: f64,
    pub lines64: f64,
    pub lines128: f64,
    /// Tier 3, the model: bytes per ray requested from each level, its hit rate.
    pub l1_bytes: f64,
    pub l1_hit: f64,
    pub l2_bytes: f64,
    pub l2_hit: f64,
    pub llc_bytes: f64,
    pub llc_hit: f64,
    pub dram_bytes: f64,
    pub dram_node_bytes: f64,
    /// Of `dram_bytes`, the stacks' (private memory: single rays, unless `memory --no-stack`).
    #[serde(default)]
    pub dram_stack_bytes: f64,
    /// DRAM energy per ray, nJ (DRAM bytes × 8 × the GPU's pJ per bit).
    pub dram_nj: f64,
    /// Rays per second DRAM bandwidth allows (millions).
    pub dram_bound_mrays: f64,
    /// DRAM bytes per ray ÷ f32's (same GPU, scene, rays, B, P).
    pub dram_vs_f32: Option<f64>,
    pub dram_node_vs_f32: Option<f64>,
    /// Rays per second the issue cycles allow (millions): `estimate`'s rays per 1000 clocks per
    /// SIMD × SIMDs × clock, where an estimate of this kernel on this family, scene and rays was
    /// given (`memory --estimate`).
    #[serde(default)]
    pub issue_bound_mrays: Option<f64>,
    /// Rays per second the L2's bandwidth allows (millions): the GPU's L2 GB/s ÷ the bytes per
    /// ray requested from the L2 (`None` in files written before it was modelled).
    #[serde(default)]
    pub l2_bound_mrays: Option<f64>,
    /// Mean latency of a wave's reading step, ns: the deepest level its lines came from
    /// (`cache::simulate`; 0 in files written before latency was modelled).
    #[serde(default)]
    pub step_ns: f64,
    /// Rays per second the latency allows with the waves resident (millions): the rays ÷ the
    /// time the waves need when every place on the GPU (units × resident waves, at most one per
    /// wave that reads) runs its waves one after another, each wave as long as the sum of its
    /// steps' latencies — their sum ÷ the places, or the longest wave where that is longer
    /// (Little's law; `None` in files written before latency was modelled).
    #[serde(default)]
    pub latency_bound_mrays: Option<f64>,
    /// The roofline: the lowest of the issue, latency, L2 and DRAM bounds, which one binds
    /// ("issue", "latency", "L2", "DRAM"), ÷ f32's bound.
    #[serde(default)]
    pub bound_mrays: f64,
    #[serde(default)]
    pub binds: String,
    #[serde(default)]
    pub bound_vs_f32: Option<f64>,
    #[serde(skip)]
    pub what: What,
}

super::key::keyed_row!(MemRow, |r| place: [&r.gpu, "", &r.scene, &r.rays], float_controls: "", packet_impl: None);

/// Sets each row's roofline (the lowest of its issue, latency, L2 and DRAM bounds; on a tie
/// DRAM, then L2, then latency) and its ratios to its f32 peer's: DRAM bytes, the nodes' DRAM
/// bytes, the bound.
pub fn set_ratios(rows: &mut [MemRow]) {
    for r in rows.iter_mut() {
        let mut bound = (r.dram_bound_mrays, "DRAM");
        for (b, name) in [(r.l2_bound_mrays, "L2"), (r.latency_bound_mrays, "latency"), (r.issue_bound_mrays, "issue")]
        {
            if let Some(b) = b.filter(|&b| b < bound.0) {
                bound = (b, name);
            }
        }
        (r.bound_mrays, r.binds) = (bound.0, bound.1.into());
    }
    let div = |a: f64, b: f64| (b > 0.0).then(|| a / b);
    let q: Vec<_> = rows
        .iter()
        .map(|r| match f32_peer(r, rows.iter()) {
            Some(f) if r.ok() => (
                div(r.dram_bytes, f.dram_bytes),
                div(r.dram_node_bytes, f.dram_node_bytes),
                div(r.bound_mrays, f.bound_mrays),
            ),
            _ => (None, None, None),
        })
        .collect();
    for (r, (a, b, c)) in rows.iter_mut().zip(q) {
        (r.dram_vs_f32, r.dram_node_vs_f32, r.bound_vs_f32) = (a, b, c);
    }
}

/// One line of `memory.csv`.
#[derive(Serialize)]
struct Record<'a> {
    gpu: &'a str,
    scene: &'a str,
    triangles: usize,
    rays: &'a str,
    ray_count: usize,
    kernel: &'a str,
    layout: &'a str,
    math: &'a str,
    #[serde(rename = "B")]
    branching: usize,
    #[serde(rename = "P")]
    packet: usize,
    wave: usize,
    resident: usize,
    resident_from: &'a str,
    #[serde(serialize_with = "display")]
    status: &'a Status,
    #[serde(serialize_with = "fixed::<1, _>")]
    node_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    vert_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    id_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    enter_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    stack_bytes: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines32_alone: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines64_alone: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines128_alone: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines32: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines64: f64,
    #[serde(serialize_with = "fixed::<2, _>")]
    lines128: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    l1_bytes: f64,
    #[serde(serialize_with = "fixed::<4, _>")]
    l1_hit: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    l2_bytes: f64,
    #[serde(serialize_with = "fixed::<4, _>")]
    l2_hit: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    llc_bytes: f64,
    #[serde(serialize_with = "fixed::<4, _>")]
    llc_hit: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    dram_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    dram_node_bytes: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    dram_stack_bytes: f64,
    #[serde(serialize_with = "fixed::<3, _>")]
    dram_nj: f64,
    #[serde(serialize_with = "fixed::<1, _>")]
    dram_bound_mrays: f64,
    #[serde(serialize_with = "opt_display")]
    dram_vs_f32: Option<f64>,
    #[serde(serialize_with = "opt_display")]
    dram_node_vs_f32: Option<f64>,
    #[serde(serialize_with = "opt_fixed::<1, _>")]
    l2_bound_mrays: Option<f64>,
    #[serde(serialize_with = "fixed::<1, _>")]
    step_ns: f64,
    #[serde(serialize_with = "opt_fixed::<1, _>")]
    latency_bound_mrays: Option<f64>,
    #[serde(serialize_with = "opt_fixed::<1, _>")]
    issue_bound_mrays: Option<f64>,
    #[serde(serialize_with = "fixed::<1, _>")]
    bound_mrays: f64,
    binds: &'a str,
    #[serde(serialize_with = "opt_display")]
    bound_vs_f32: Option<f64>,
}

/// memory.csv.
pub fn csv(rows: &[MemRow]) -> anyhow::Result<Vec<u8>> {
    super::csvx::to_bytes(rows.iter().map(|r| Record {
        gpu: &r.gpu,
        scene: &r.scene,
        triangles: r.triangles,
        rays: &r.rays,
        ray_count: r.ray_count,
        kernel: &r.kernel,
        layout: &r.layout,
        math: &r.math,
        branching: r.branching,
        packet: r.packet,
        wave: r.wave,
        resident: r.resident,
        resident_from: &r.resident_from,
        status: &r.status,
        node_bytes: r.node_bytes,
        vert_bytes: r.vert_bytes,
        id_bytes: r.id_bytes,
        enter_bytes: r.enter_bytes,
        stack_bytes: r.stack_bytes,
        lines32_alone: r.lines32_alone,
        lines64_alone: r.lines64_alone,
        lines128_alone: r.lines128_alone,
        lines32: r.lines32,
        lines64: r.lines64,
        lines128: r.lines128,
        l1_bytes: r.l1_bytes,
        l1_hit: r.l1_hit,
        l2_bytes: r.l2_bytes,
        l2_hit: r.l2_hit,
        llc_bytes: r.llc_bytes,
        llc_hit: r.llc_hit,
        dram_bytes: r.dram_bytes,
        dram_node_bytes: r.dram_node_bytes,
        dram_stack_bytes: r.dram_stack_bytes,
        dram_nj: r.dram_nj,
        dram_bound_mrays: r.dram_bound_mrays,
        dram_vs_f32: r.dram_vs_f32.map(|v| (v * 1e4).round() / 1e4),
        dram_node_vs_f32: r.dram_node_vs_f32.map(|v| (v * 1e4).round() / 1e4),
        l2_bound_mrays: r.l2_bound_mrays,
        step_ns: r.step_ns,
        latency_bound_mrays: r.latency_bound_mrays,
        issue_bound_mrays: r.issue_bound_mrays,
        bound_mrays: r.bound_mrays,
        binds: &r.binds,
        bound_vs_f32: r.bound_vs_f32.map(|v| (v * 1e4).round() / 1e4),
    }))
}

/// What can bind a roofline, as `binds` names it.
const BINDS: [&str; 4] = ["issue", "latency", "L2", "DRAM"];

/// Coherent (primary) or incoherent (every other ray kind) rays.
fn coherence(rays: &str) -> &'static str {
    if rays == "primary" {
        "coherent"
    } else {
        "incoherent"
    }
}

/// One verdict per GPU and coherence: among the built-in kernels of the conservative layouts
/// (those that return f32's hits), the one whose roofline bound is highest as a ratio to f32's
/// (mean over scenes and ray sets), by how much, and what binds it in how many ray sets (issue,
/// where `estimate` gave cycles; latency; the L2; DRAM).
pub fn verdicts(rows: &[MemRow]) -> Vec<String> {
    use std::collections::BTreeMap;
    // (gpu, coherence) → kernel label → (sum of bound ratios, of DRAM ratios, [issue, latency,
    // L2, DRAM] bound counts, n)
    type Acc = BTreeMap<String, (f64, f64, [usize; 4], usize)>;
    let mut acc: BTreeMap<(String, &str), Acc> = BTreeMap::new();
    let conservative = |r: &MemRow| r.what.builtin().is_some_and(|k| k.variant.layout.info().conservative);
    for r in rows.iter().filter(|r| r.ok() && conservative(r)) {
        let (Some(q), Some(d)) = (r.bound_vs_f32, r.dram_vs_f32) else { continue };
        let label = format!("{} {} B={} P={}", r.layout, r.math, r.branching, r.packet);
        let e =
            acc.entry((r.gpu.clone(), coherence(&r.rays))).or_default().entry(label).or_insert((0.0, 0.0, [0; 4], 0));
        e.0 += q;
        e.1 += d;
        if let Some(i) = BINDS.iter().position(|b| *b == r.binds) {
            e.2[i] += 1;
        }
        e.3 += 1;
    }
    let mut out = Vec::new();
    for ((gpu, kind), m) in acc {
        let best = m.iter().max_by(|a, b| (a.1 .0 / a.1 .3 as f64).total_cmp(&(b.1 .0 / b.1 .3 as f64)));
        if let Some((l, (q, d, counts, n))) = best {
            let modelled = rows.iter().any(|r| r.gpu == gpu && r.issue_bound_mrays.is_some());
            let binds = match counts.iter().position(|&c| c == *n) {
                Some(i) => format!("{} binds in every ray set", BINDS[i]),
                None => {
                    let parts: Vec<String> =
                        BINDS.iter().zip(counts).filter(|x| *x.1 > 0).map(|(b, c)| format!("{b} in {c}")).collect();
                    format!("binds: {} of {n} ray sets", parts.join(", "))
                }
            };
            let binds =
                if modelled { binds } else { format!("{binds} (memory alone: no cycle model joined for this GPU)") };
            // A file written before the L2 or the latency bound was modelled.
            let no_l2 = rows.iter().any(|r| r.gpu == gpu && r.l2_bound_mrays.is_none());
            let binds = if no_l2 { format!("{binds} (no L2 bound in this file)") } else { binds };
            let no_lat = rows.iter().any(|r| r.gpu == gpu && r.latency_bound_mrays.is_none());
            let binds = if no_lat { format!("{binds} (no latency bound in this file)") } else { binds };
            // Resident waves from a compiler's occupancy (`memory --compilers`): name its release.
            let from = rows.iter().filter(|r| r.gpu == gpu).find_map(|r| resident_release(&r.resident_from));
            let binds = match from {
                Some(rel) => format!("{binds}; resident waves: {rel}'s occupancy"),
                None => binds,
            };
            let n = *n as f64;
            out.push(format!(
                "{gpu}, {kind} rays: **{l}**, roofline bound {:.2}× f32's, DRAM bytes {:.2}× f32's; {binds} (model)",
                q / n,
                d / n
            ));
        }
    }
    out
}

/// memory.md: the verdicts first, then per GPU, scene and ray set every kernel's bytes.
pub fn markdown(rows: &[MemRow], gpus_table: &str) -> String {
    let mut md = String::from("# The memory side of a ray\n\n## Verdict per GPU (the model's)\n\n");
    md += "Among the conservative layouts' kernels, the highest roofline bound as a ratio to f32's at the same \
           B and P (mean over scenes and ray sets): the lowest of the rays/s DRAM bandwidth allows, the rays/s the \
           L2's bandwidth allows, the rays/s the latency allows with the waves resident and, where \
           `memory --estimate` joined AMD's cycle estimate, the rays/s issue allows.\n\n";
    for v in verdicts(rows) {
        md += &format!("- {v}\n");
    }
    md += "\n## What each tier is\n\n- requested bytes per ray (exact, from the CPU reference's walk): nodes, \
           triangle vertices (36 B a test), ids (4 B a test the certified test does not reject), enter (what a \
           kernel that derives a child's entry when it enters it re-reads of the parent node: its child word, and \
           the child's box where the ray hit it), stack (what the \
           kernel's pushes and pops move: an entry per inner child but the nearest, or a group per visit);\n- \
           distinct lines (exact): per ray alone and per wave with its lanes coalesced at each lockstep step — the \
           stacks' too, for single rays: in private memory, each wave's lanes interleaved dword by dword (unless \
           `--no-stack`);\n- the cache model: an L1 per unit shared by its resident waves, the L2, the last-level \
           cache, DRAM (LRU, sets by address modulo, no prefetch, no compression, no texture path; stores kept by a \
           write-back L1 or passed through a write-through one, taken without a fill, dirty lines written back \
           when evicted), each resident wave's stacks in a private region of its own: a model, not a \
           measurement.\n\n";
    md += gpus_table;
    md += &resident_section(rows);
    let mut groups: Vec<(&str, &str, &str)> =
        rows.iter().map(|r| (r.gpu.as_str(), r.scene.as_str(), r.rays.as_str())).collect();
    groups.dedup();
    for (g, scene, kind) in groups {
        let rs: Vec<&MemRow> = rows.iter().filter(|r| r.gpu == g && r.scene == scene && r.rays == kind).collect();
        md += &format!(
            "\n## {g}, {scene} ({} triangles), {kind} rays ({}, wave {})\n\n",
            rs[0].triangles, rs[0].ray_count, rs[0].wave
        );
        md += "| kernel | node B | tri B | id B | enter B | lines/ray 64 B alone | wave | L1 B | L1 hit | L2 B | L2 hit | LLC B | LLC hit | DRAM B | DRAM node B | DRAM stack B | ÷ f32 | nodes ÷ f32 | DRAM nJ | Mrays/s DRAM-bound | L2-bound | step ns | latency-bound | issue-bound | binds | bound ÷ f32 | resident waves |\n";
        md += "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|\n";
        for r in rs {
            let q = |x: Option<f64>| x.map_or("–".to_string(), |v| format!("{v:.2}"));
            md += &format!(
                "| {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {:.0} | {:.3} | {:.0} | {:.3} | {:.0} | {:.3} | {:.0} | {:.0} | {:.0} | {} | {} | {:.2} | {:.0} | {} | {:.0} | {} | {} | {} | {} | {} |\n",
                r.kernel,
                r.node_bytes,
                r.vert_bytes,
                r.id_bytes,
                r.enter_bytes,
                r.lines64_alone,
                r.lines64,
                r.l1_bytes,
                r.l1_hit,
                r.l2_bytes,
                r.l2_hit,
                r.llc_bytes,
                r.llc_hit,
                r.dram_bytes,
                r.dram_node_bytes,
                r.dram_stack_bytes,
                q(r.dram_vs_f32),
                q(r.dram_node_vs_f32),
                r.dram_nj,
                r.dram_bound_mrays,
                r.l2_bound_mrays.map_or("–".to_string(), |v| format!("{v:.0}")),
                r.step_ns,
                r.latency_bound_mrays.map_or("–".to_string(), |v| format!("{v:.0}")),
                r.issue_bound_mrays.map_or("–".to_string(), |v| format!("{v:.0}")),
                r.binds,
                q(r.bound_vs_f32),
                r.resident
            );
        }
    }
    md
}

/// The compilers release a row's `resident_from` names (its driver's, [`super::isa::release`]),
/// `None` where the figure is assumed (`memory::resident` writes it).
pub fn resident_release(from: &str) -> Option<String> {
    let driver = from.split(": ").next().filter(|_| !from.is_empty() && !from.starts_with("assumed"))?;
    Some(super::isa::release(driver))
}

/// Where the rows' resident waves come from a compiler's occupancy (`memory --compilers`):
/// per GPU and kernel, the waves and the figure they were made from ("" where every row's are
/// the model's assumed figure).
fn resident_section(rows: &[MemRow]) -> String {
    if rows.iter().all(|r| r.resident_from.is_empty() || r.resident_from == "assumed") {
        return String::new();
    }
    let mut md = String::from(
        "## Resident waves per unit, from the compilers' occupancy (`memory --compilers`)\n\n\
         Each kernel's waves per unit in the cache model: the occupancy its GPU's compiler reported for it \
         (waves per SIMD × SIMDs per CU on AMD), or the model's assumed figure where no compiler here \
         reports one.\n\n| GPU | kernel | waves/unit | from |\n|---|---|---:|---|\n",
    );
    let mut seen: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        if seen.contains(&(r.gpu.as_str(), r.kernel.as_str())) {
            continue;
        }
        seen.push((&r.gpu, &r.kernel));
        md += &format!("| {} | {} | {} | {} |\n", r.gpu, r.kernel, r.resident, r.resident_from);
    }
    md + "\n"
}

/// The rows of `dir/memory.json`, `None` where there is none.
pub fn read(dir: &Path) -> anyhow::Result<Option<Vec<MemRow>>> {
    let p = dir.join("memory.json");
    if !p.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    let rows: Vec<MemRow> = serde_json::from_str(&text)
        .with_context(|| format!("{}: not the rows `halftrace memory` writes", p.display()))?;
    Ok(Some(rows.into_iter().map(MemRow::typed).collect()))
}

/// The verdicts as a section for `report.md` and `headline.md` ("" without rows).
pub fn verdict_section(rows: &[MemRow]) -> String {
    let v = verdicts(rows);
    if v.is_empty() {
        return String::new();
    }
    let mut md =
        String::from("## Verdict per GPU: the memory side (`halftrace memory`, a cache model, not a measurement)\n\n");
    for l in v {
        md += &format!("- {l}\n");
    }
    md + "\nDetails: [memory.md](memory.md).\n\n"
}
