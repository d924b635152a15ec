//! Every layout against f32: bytes, work and speed per layout and B.

use super::*;

/// One (device, layout/math label, B) point of the layouts table.
#[derive(Clone, Debug, Default)]
pub struct LayoutPoint {
    pub n: usize,
    /// Sums of the per-(scene, rays) ratios to f32: Mrays/s, BVH bytes, nodes, box tests,
    /// triangle tests.
    pub ratio: [f64; 5],
    pub node_bytes_per_ray: f64,
    pub stack_bytes: u64,
    pub differs: usize,
    pub false_misses: usize,
    pub max_dt: f64,
}

/// A row's layout label: the layout, its math mode where it has several, `fc off` builds marked.
pub fn layout_label(r: &Row) -> String {
    let several = r.what.layout().map(|l| l.info().maths.len() > 1).unwrap_or(true);
    let mut s = if several { format!("{}/{}", r.layout, r.math) } else { r.layout.clone() };
    if r.float_controls == "off" {
        s += " (fc off)";
    }
    s
}

/// Every BVH layout and math mode at each B (P = 1) against f32 at the same B, per device:
/// (device, registry order, label, B) → point.
pub fn layout_points(rows: &[Row]) -> BTreeMap<(String, usize, String, usize), LayoutPoint> {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status.is_ok() && r.packet == 1 && has_counters(&r.layout)).collect();
    let mut acc: BTreeMap<(String, usize, String, usize), LayoutPoint> = BTreeMap::new();
    for h in ok.iter().filter(|r| r.what.kernel().is_some()) {
        let Some(f) = crate::report::key::f32_peer(*h, ok.iter().copied()) else {
            continue;
        };
        let div = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
        let e = acc
            .entry((h.device.clone(), crate::report::rows::order(&h.layout), layout_label(h), h.branching))
            .or_default();
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

/// The layouts table: which reduced-precision layout, at which B, on this device.
pub fn layouts_table(points: &BTreeMap<(String, usize, String, usize), LayoutPoint>) -> String {
    if points.is_empty() {
        return String::new();
    }
    let mut md = String::from(concat!(
        "## Layouts: every layout and math mode ÷ f32, per B (P = 1)\n\n",
        "Means over scenes and ray kinds of each variant's ratio to `f32` at the same B (user kernels excluded). ",
        "Mrays/s above 1: faster than f32; BVH bytes, nodes, box and triangle tests below 1: smaller / less work. ",
        "Node bytes/ray = nodes visited × node bytes; stack bytes = the kernel's per-ray stack. ≠ f32, false ",
        "misses: rays summed over scenes and ray kinds (0 for every conservative layout; `f16h-poster` is the ",
        "poster's algorithm without an error bound); max |Δt| over them.\n\n",
    ));
    md += &header(&[
        ("device", false),
        ("layout", false),
        ("B", true),
        ("Mrays/s ÷ f32", true),
        ("BVH bytes ÷ f32", true),
        ("node bytes/ray", true),
        ("nodes ÷ f32", true),
        ("box tests ÷ f32", true),
        ("tri tests ÷ f32", true),
        ("stack bytes/ray", true),
        ("≠ f32", true),
        ("false misses", true),
        ("max abs Δt", true),
    ]);
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
    md + "\n![layouts](layouts.png)\n\n"
}
