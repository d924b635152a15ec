//! `halftrace estimate`: what a ray costs in cycles on GPUs we do not have, from the
//! compilers' own cost models.
//!
//! This part reads AMD's. ACO estimates each kernel's cycles (`Latency`: one wave, issue
//! plus stall cycles) by weighting every block of the final program with the trips it assumes
//! for the loops around it ([`crate::isa::aco`]). Taken apart, that estimate gives, per loop of
//! the kernel, the cycles of one pass through its own blocks and the share of the estimate it
//! carries; rebuilt from those parts it must equal ACO's figure, which every row checks.
//!
//! Then the rays take the place of ACO's assumed trips ([`ray_rows`]). Three loops of a
//! kernel are named by the program's shape ([`roles`]): the traversal loop (the
//! outermost loop that carries most of the estimate), the triangle loop (the loop inside it
//! with the costliest pass) and, where the compiler kept it a loop, the child-slot loop
//! between them. The CPU reference counts, per wave of the device's wave size in lockstep
//! (single rays, or packets of P rays that step together), how often each runs
//! ([`crate::layout::traverse::LoopWork`]): a pass per node entered, B slot passes per visit,
//! and per visit a triangle pass per triangle of the lane that tests the most (the kernels run
//! a visit's leaves through one loop, `test_leaves`). The kernels unroll their child-slot
//! loops, so no compiler keeps one around the triangle loop today; the role stays for one that
//! would.
//! Every other loop (an exact division's corrections, a per-axis loop the compiler kept)
//! keeps ACO's assumed trips relative to the nearest of those three around it, or runs as
//! ACO assumes when outside them. Inside the triangle loop the named sides of the triangle
//! test ([`crate::base::tri::Branch`]), found in ACO's program by a build with a marker at the
//! start of each ([`aco::branch_sides`]), run in as many passes as a wave's lanes take them
//! ([`crate::layout::traverse::branch_work`]); every other branch keeps ACO's weights (0.5 for
//! a uniform if, 0.75 for a divergent one), and the row keeps ACO's figure beside
//! (`aco_branches`). It is the compiler's model, one wave, issue plus stall cycles, no latency
//! hidden: an estimate, not a measurement.

mod rays;

pub use crate::report::estimate::{RayRow, Split};
pub use rays::{ray_cycles, ray_rows, roles, roles_at, Built, BuiltKernel, LoopCosts, Rays, Roles};

use crate::base::Status;
use crate::gpu::null;
use crate::isa::{self, aco, Matrix};
use crate::layout::LayoutId;
use crate::report::csvx::{display, opt_display};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A loop's part of a kernel's estimate (`header` `None`: the blocks outside every loop).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopCost {
    /// The loop's header block (`BB<n>`), `None` outside every loop.
    pub header: Option<usize>,
    /// 0 outside every loop, 1 for an outermost loop.
    pub depth: u32,
    /// Cycles of one pass through the loop's own blocks (those of loops inside it apart),
    /// ACO's if factors inside it applied ([`aco::Program::per_pass`]).
    pub cycles_per_trip: f64,
    /// How many passes ACO assumes per run of the kernel (its and its outer loops' trips,
    /// times the weight of the ifs it is entered in).
    pub aco_passes: f64,
    /// `cycles_per_trip × aco_passes` ÷ the kernel's estimate.
    pub share: f64,
}

/// One kernel on one family.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub family: String,
    pub generation: String,
    /// The driver that built it, naming its Mesa release (`radv Mesa 26.2.6-1`).
    pub driver: String,
    pub kernel: String,
    pub layout: String,
    pub math: String,
    pub branching: usize,
    pub packet: usize,
    pub status: Status,
    /// ACO's `Latency` statistic.
    pub aco_latency: Option<f64>,
    /// The same figure rebuilt from the blocks (unrounded; ACO prints it to six decimals).
    pub rebuilt: Option<f64>,
    pub printed: Option<f64>,
    /// Waves per SIMD ACO gives the kernel (`num_waves`).
    pub waves: Option<f64>,
    pub loops: Vec<LoopCost>,
    /// The kernel, typed: its isa row's.
    #[serde(skip)]
    pub what: crate::report::What,
}

/// How far the rebuilt figure may be from the printed one: ACO prints it with `%f`.
pub const TOLERANCE: f64 = 1e-6;

/// A kernel's row from its isa row and ACO's program.
fn row(family: &str, generation: &str, r: &crate::report::isa::IsaRow, p: Result<aco::Program, String>) -> Row {
    let mut row = Row {
        family: family.into(),
        generation: generation.into(),
        driver: r.driver.clone(),
        kernel: r.kernel.clone(),
        layout: r.layout.clone(),
        math: r.math.clone(),
        branching: r.branching,
        packet: r.packet,
        status: r.status.clone(),
        aco_latency: r.stats.get("Latency").copied(),
        what: r.what.clone(),
        ..Row::default()
    };
    let p = match p {
        Ok(p) => p,
        Err(e) => {
            if row.status.is_ok() {
                row.status = Status::Failed(e);
            }
            return row;
        }
    };
    let total = p.aco_latency();
    row.rebuilt = Some(total);
    row.printed = Some(p.printed_latency);
    row.waves = p.printed.get("num_waves").copied();
    row.loops = std::iter::once(None)
        .chain(p.loops.iter().map(Some))
        .map(|l| {
            let (cycles, passes) = (p.per_pass(l), l.map_or(1.0, |l| p.aco_passes(l)));
            LoopCost {
                header: l.map(|l| l.header),
                depth: l.map_or(0, |l| l.depth),
                cycles_per_trip: cycles,
                aco_passes: passes,
                share: if total > 0.0 { cycles * passes / total } else { 0.0 },
            }
        })
        .collect();
    let parts = p.cycles(|l| p.aco_passes(l));
    if (total - p.printed_latency).abs() > TOLERANCE
        || row.aco_latency != Some(total.round())
        || (parts - total).abs() > TOLERANCE * total.max(1.0)
    {
        row.status = Status::Failed(format!(
            "{family} {}: rebuilt {total:.6} cycles ({parts:.6} from its loops), but ACO printed {:.6} (statistic {:?})",
            r.kernel, p.printed_latency, row.aco_latency
        ));
    }
    row
}

/// One AMD family's kernels of `matrix` (for `layouts`), built as they are and with their named
/// branches marked, in two child processes at once ([`isa::aco_programs`]): each kernel's isa
/// row, ACO's program and the sides of its triangle test the marked build names in it
/// ([`aco::branch_sides`]), or why not.
pub fn programs(
    exe: &Path,
    family: &str,
    matrix: Matrix,
    layouts: &[LayoutId],
    amd: Option<&Path>,
) -> anyhow::Result<Vec<BuiltKernel>> {
    let (real, marked) = rayon::join(
        || isa::aco_programs(exe, family, matrix, layouts, amd, false),
        || isa::aco_programs(exe, family, matrix, layouts, amd, true),
    );
    let (real, marked) = (real?, marked?);
    anyhow::ensure!(
        real.len() == marked.len(),
        "--family {family}: the marked build made {} kernels, the real one {}",
        marked.len(),
        real.len()
    );
    Ok(real
        .into_iter()
        .zip(marked)
        .map(|((r, p), (mr, mp))| {
            let sides = match (&p, mp) {
                (Ok(p), Ok(mp)) if mr.kernel == r.kernel => aco::branch_sides(&mp, p),
                (Ok(_), Ok(_)) => Err(format!("the marked build is {}, not {}", mr.kernel, r.kernel)),
                (_, Err(e)) => Err(format!("the marked build: {e}")),
                (Err(e), _) => Err(e.clone()),
            };
            (r, p, sides)
        })
        .collect())
}

/// Builds `matrix` (for `layouts`; empty: all) on each AMD family, one child process each,
/// as many at once as there are cores, takes each kernel's estimate apart and weighs its
/// loops with `rays`; rows in family order.
pub fn run(
    exe: &Path,
    families: &[String],
    matrix: Matrix,
    layouts: &[LayoutId],
    rays: &Rays,
    amd: Option<&Path>,
) -> anyhow::Result<(Vec<Row>, Vec<RayRow>)> {
    use rayon::prelude::*;
    let built: Vec<Vec<_>> =
        families.par_iter().map(|f| programs(exe, f, matrix, layouts, amd)).collect::<anyhow::Result<_>>()?;
    let by_family: Vec<(String, &Built)> = families.iter().cloned().zip(built.iter().map(Vec::as_slice)).collect();
    let ray_out = ray_rows(&by_family, rays)?;
    let mut rows = Vec::new();
    for (f, b) in families.iter().zip(built) {
        let generation = null::family(f).map_or("", |x| x.generation);
        rows.extend(b.into_iter().map(|(r, p, _)| row(f, generation, &r, p)));
    }
    Ok((rows, ray_out))
}

/// Every file of an `estimate` folder: estimate.csv (ACO's estimate per kernel, taken apart),
/// estimate-rays.csv and .json (per ray set), the plot, and estimate.md — its one renderer:
/// the kernels' loops, the cycles per ray ([`crate::report::estimate::section`], which a
/// merged report shows too) and the other vendors' whole-shader figures.
pub fn write(
    out: &std::path::Path,
    rows: &[Row],
    ray_rows: &[crate::report::estimate::RayRow],
    vendor_rows: &[crate::report::isa::IsaRow],
) -> anyhow::Result<()> {
    crate::fsx::write_atomic(&out.join("estimate.csv"), &csv(rows)?)?;
    crate::report::estimate::write(ray_rows, out)?;
    crate::report::estimate::plot(ray_rows, out)?;
    let md = markdown(rows)
        + &crate::report::estimate::section(ray_rows)
        + &crate::report::estimate::vendors_section(vendor_rows);
    crate::fsx::write_atomic(&out.join("estimate.md"), md.as_bytes())
}

/// The loops of a row, largest share first (the blocks outside every loop last).
fn by_share(r: &Row) -> Vec<&LoopCost> {
    let mut ls: Vec<&LoopCost> = r.loops.iter().filter(|l| l.header.is_some()).collect();
    ls.sort_by(|a, b| b.share.total_cmp(&a.share));
    ls
}

/// estimate.md's first part: per family, each kernel's ACO estimate, rebuilt, and its three costliest
/// loops.
fn markdown(rows: &[Row]) -> String {
    let mut md = String::from("# Estimated cycles: ACO's model taken apart per loop\n\n");
    md += "ACO's `Latency` (one wave, issue plus stall cycles) for each kernel, rebuilt from the final program's \
           blocks with the weights ACO gives them, and the loops that carry it: the cycles of one pass through a \
           loop's own blocks and its share of the estimate under ACO's assumed trips (8 for an outermost loop, 4 at \
           the second level, 2 deeper). **It is the compiler's model, not a measurement**, and its trips are \
           assumptions; `BB<n>` is the loop's header block in the `--disasm` listings.\n\n";
    let mut families: Vec<&str> = rows.iter().map(|r| r.family.as_str()).collect();
    families.dedup();
    for f in families {
        let fr: Vec<&Row> = rows.iter().filter(|r| r.family == f).collect();
        md += &format!("## {f} ({}), {}\n\n", fr[0].generation, crate::report::isa::release(&fr[0].driver));
        md += "| kernel | layout | math | B | P | ACO Latency | rebuilt | waves | loops | costliest loops (depth: cycles per pass × passes = share) | outside loops | status |\n";
        md += "|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---|\n";
        for r in fr {
            let num = |x: Option<f64>, d: usize| x.map_or("–".to_string(), |v| format!("{v:.d$}"));
            let top: Vec<String> = by_share(r)
                .iter()
                .take(3)
                .map(|l| {
                    format!(
                        "BB{} ({}: {:.1} × {} = {:.1}%)",
                        l.header.unwrap_or(0),
                        l.depth,
                        l.cycles_per_trip,
                        l.aco_passes,
                        100.0 * l.share
                    )
                })
                .collect();
            let outside = r.loops.iter().find(|l| l.header.is_none()).map_or(0.0, |l| l.share);
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1}% | {} |\n",
                r.kernel,
                r.layout,
                r.math,
                r.branching,
                r.packet,
                num(r.aco_latency, 0),
                num(r.rebuilt, 3),
                num(r.waves, 0),
                r.loops.len().saturating_sub(1),
                top.join("; "),
                100.0 * outside,
                r.status
            );
        }
        md += "\n";
    }
    md
}

/// One line of `estimate.csv`.
#[derive(Serialize)]
struct Record<'a> {
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
    #[serde(serialize_with = "display")]
    status: &'a Status,
    #[serde(serialize_with = "opt_display")]
    aco_latency: Option<f64>,
    #[serde(serialize_with = "opt_display")]
    rebuilt: Option<f64>,
    #[serde(serialize_with = "opt_display")]
    waves: Option<f64>,
    #[serde(rename = "loop")]
    name: String,
    depth: u32,
    #[serde(rename = "cycles_per_pass", serialize_with = "display")]
    cycles_per_trip: f64,
    #[serde(serialize_with = "display")]
    aco_passes: f64,
    #[serde(serialize_with = "display")]
    share: f64,
}

/// estimate.csv: one line per kernel and loop (`outside` for the blocks outside every loop).
pub fn csv(rows: &[Row]) -> anyhow::Result<Vec<u8>> {
    let empty = [LoopCost::default()];
    let records = rows.iter().flat_map(|r| {
        let loops: &[LoopCost] = if r.loops.is_empty() { &empty } else { &r.loops };
        loops.iter().map(move |l| Record {
            family: &r.family,
            generation: &r.generation,
            driver: &r.driver,
            kernel: &r.kernel,
            layout: &r.layout,
            math: &r.math,
            branching: r.branching,
            packet: r.packet,
            status: &r.status,
            aco_latency: r.aco_latency,
            rebuilt: r.rebuilt,
            waves: r.waves,
            name: match l.header {
                Some(h) => format!("BB{h}"),
                None if r.loops.is_empty() => String::new(),
                None => "outside".into(),
            },
            depth: l.depth,
            cycles_per_trip: l.cycles_per_trip,
            aco_passes: l.aco_passes,
            share: l.share,
        })
    });
    crate::report::csvx::to_bytes(records)
}
