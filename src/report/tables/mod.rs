//! The report's tables, each computed from result rows and rendered as Markdown: the
//! headline f16h ÷ f32 ratios by B and by P, storage against arithmetic, every layout against
//! f32, each baseline against every variant, and every row.

//!
//! Files: [`ratios`] (the headline ratios by B and P, storage against arithmetic, the device
//! headline), [`layouts`] (every layout against f32), [`baselines`] (each baseline against
//! every variant); every row is here.

use super::rows::{has_counters, Row};
use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use std::collections::BTreeMap;

mod baselines;
mod layouts;
mod ratios;

pub use baselines::against_baselines;
pub use layouts::{layout_label, layout_points, layouts_table, LayoutPoint};
pub use ratios::{device_headline, headline, ratios, separated_effects, series, Ratio};

/// A Markdown table's header and alignment row from `(title, right-aligned)` columns.
pub(crate) fn header(columns: &[(&str, bool)]) -> String {
    let titles: Vec<&str> = columns.iter().map(|c| c.0).collect();
    let align: Vec<&str> = columns.iter().map(|c| if c.1 { "---:" } else { "---" }).collect();
    format!("| {} |\n|{}|\n", titles.join(" | "), align.join("|"))
}

pub fn fmt(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "–".into()
    }
}

/// Every row: identity, speed, work, bytes, agreement with f32 and status.
pub fn every_row(rows: &[Row]) -> String {
    let mut md = String::from(concat!(
        "## Every variant\n\n",
        "Float controls `on`: the kernel declares round-to-nearest-even and inf/NaN preservation and matches its ",
        "CPU reference bit for bit; `off`: a build whose hits stay exact without them (used on devices that lack ",
        "them, or forced with `--float-controls off`). For baselines (`rq`, `rt`, `embree`), B, P and the work counters ",
        "do not apply, and for user kernels that do not count, the work counters are not measured (both shown as ",
        "–); a baseline's bytes are its own acceleration structures. ≠ f32 counts rays that hit where f32 misses or ",
        "the reverse, or hit another triangle at a t more than 1e-5 (relative) away.\n\n",
    ));
    md += &header(&[
        ("device", false),
        ("scene", false),
        ("rays", false),
        ("kernel", false),
        ("float controls", false),
        ("Mrays/s median (min–max)", false),
        ("ms", true),
        ("nodes/ray", true),
        ("box/ray", true),
        ("tri/ray", true),
        ("re-anchors/ray", true),
        ("SIMD util.", true),
        ("BVH bytes", true),
        ("build ms", true),
        ("B/node", true),
        ("stack B/ray", true),
        ("≠ f32", true),
        ("false misses", true),
        ("max abs Δt", true),
        ("status", false),
    ]);
    for x in rows {
        let na = !has_counters(&x.layout) || x.nodes_per_ray.is_nan();
        let c = |v: String| if na { "–".to_string() } else { v };
        let cells = [
            x.device.clone(),
            format!("{} ({} tris)", x.scene, x.triangles),
            format!("{} ({})", x.rays, x.ray_count),
            x.kernel.clone(),
            if x.float_controls.is_empty() { "n/a".into() } else { x.float_controls.clone() },
            format!("{:.2} ({:.2}–{:.2})", x.mrays_median, x.mrays_min, x.mrays_max),
            format!("{:.3}", x.ms_median),
            c(format!("{:.2}", x.nodes_per_ray)),
            c(format!("{:.2}", x.box_tests_per_ray)),
            c(format!("{:.2}", x.tri_tests_per_ray)),
            c(format!("{:.3}", x.reanchors_per_ray)),
            c(format!("{:.1}%", 100.0 * x.simd_utilisation)),
            x.bvh_bytes.to_string(),
            format!("{:.2}", x.build_ms),
            c(x.bytes_per_node.to_string()),
            c(x.stack_bytes_per_ray.to_string()),
            x.differs_from_f32.to_string(),
            x.false_misses.to_string(),
            format!("{:.3e}", x.max_abs_dt),
            x.status.to_string(),
        ];
        md += &format!("| {} |\n", cells.join(" | "));
    }
    md
}
