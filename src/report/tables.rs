//! The report's tables, each computed from result rows and rendered as Markdown: the
//! headline f16h ÷ f32 ratios by B and by P, storage against arithmetic, every layout against
//! f32, each baseline against every variant, and every row.

use super::rows::{has_counters, Row};
use crate::baseline::BaselineId;
use crate::layout::LayoutId;
use std::collections::BTreeMap;

/// A Markdown table's header and alignment row from `(title, right-aligned)` columns.
fn header(columns: &[(&str, bool)]) -> String {
    let titles: Vec<&str> = columns.iter().map(|c| c.0).collect();
    let align: Vec<&str> = columns.iter().map(|c| if c.1 { "---:" } else { "---" }).collect();
    format!("| {} |\n|{}|\n", titles.join(" | "), align.join("|"))
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

/// Pairs f16h rows in the poster's fp16 math with the f32 row of the same device, scene, rays,
/// B and P.
pub fn ratios(rows: &[Row]) -> Vec<Ratio> {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status.is_ok()).collect();
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
pub fn separated_effects(rows: &[Row]) -> String {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status.is_ok()).collect();
    // (device, B, P) → math → (sum of f16h ÷ f32, count)
    type Sums = BTreeMap<(String, usize, usize), BTreeMap<String, (f64, usize)>>;
    let mut acc: Sums = BTreeMap::new();
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
    let mut md = String::from(concat!(
        "## Storage vs arithmetic: f16h math modes ÷ f32 (Mrays/s)\n\n",
        "f16 = the poster's (fp16 box tests and origin moves); f32 = the same fp16 nodes widened on load, ",
        "fp32 arithmetic; mixed = fp16 differences and products, fp32 min/max/compare. Above 1: faster than f32. ",
        "Node bytes per ray = nodes visited × node bytes. Raw fp16:fp32 = the device's own arithmetic ratio ",
        "(`halftrace devices --arith`).\n\n",
    ));
    md += &header(&[
        ("device", false),
        ("B", true),
        ("P", true),
        ("f16 ÷ f32", true),
        ("f32 ÷ f32", true),
        ("mixed ÷ f32", true),
        ("node bytes/ray f32", true),
        ("f16h/f16", true),
        ("f16h/f32", true),
        ("raw fp16:fp32", true),
    ]);
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
    let several = LayoutId::parse(&r.layout).map(|l| l.info().maths.len() > 1).unwrap_or(true);
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
    for h in ok.iter().filter(|r| LayoutId::parse(&r.layout).is_ok() && !r.kernel.is_empty()) {
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
        let e = acc.entry((h.device.clone(), super::rows::order(&h.layout), layout_label(h), h.branching)).or_default();
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

/// Mean of the ratios of each series point: (device, key) → (time, nodes, box, tri, bytes).
pub fn series(r: &[Ratio], by_b: bool) -> BTreeMap<(String, usize), [f64; 5]> {
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

pub fn fmt(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "–".into()
    }
}

/// The headline tables: f16h (the poster's fp16 math) ÷ f32 by B at P = 1 and by P at B = 4.
pub fn headline(by_b: &BTreeMap<(String, usize), [f64; 5]>, by_p: &BTreeMap<(String, usize), [f64; 5]>) -> String {
    let mut md = String::from(concat!(
        "## Headline: f16h ÷ f32 (the poster's \"average differences to regular single-precision traversal\")\n\n",
        "Means over scenes and ray kinds of the per-variant ratios; time is the median GPU time, work the per-ray ",
        "counters, bytes the node arrays. Below 1: f16h is faster / does less / is smaller.\n\n",
    ));
    let cols = |key: &'static str| {
        header(&[
            ("device", false),
            (key, true),
            ("time", true),
            ("nodes visited", true),
            ("box tests", true),
            ("triangle tests", true),
            ("node bytes", true),
        ])
    };
    let line = |d: &str, k: usize, v: &[f64; 5]| {
        format!("| {d} | {k} | {} | {} | {} | {} | {} |\n", fmt(v[0]), fmt(v[1]), fmt(v[2]), fmt(v[3]), fmt(v[4]))
    };
    md += "### By branching factor (single rays, P = 1)\n\n";
    md += &cols("B");
    for ((d, b), v) in by_b {
        md += &line(d, *b, v);
    }
    md += "\n### By packet size (MBVH4, B = 4)\n\n";
    md += &cols("P");
    for ((d, p), v) in by_p {
        md += &line(d, *p, v);
    }
    md + "\n![ratio vs B](ratio_vs_b.png) ![ratio vs P](ratio_vs_p.png)\n\n"
}

/// One table per baseline with rows: every variant's Mrays/s ÷ the baseline's on the same
/// device, scene and rays.
pub fn against_baselines(rows: &[Row]) -> String {
    let mut md = String::new();
    for b in BaselineId::all() {
        let base: Vec<&Row> = rows.iter().filter(|r| r.layout == b.name() && r.status.is_ok()).collect();
        if base.is_empty() {
            continue;
        }
        md += &format!(
            "## Against `{b}` on the same device\n\n`{b}`: {}. Mrays/s of each variant ÷ Mrays/s of `{b}` for the same \
             scene and rays (above 1: faster). Its structures' size and build time are in its row.\n\n",
            b.imp().summary()
        );
        let ratio = format!("÷ {b}");
        md += &header(&[
            ("device", false),
            ("scene", false),
            ("rays", false),
            ("kernel", false),
            ("Mrays/s", true),
            (&ratio, true),
        ]);
        for x in rows.iter().filter(|r| r.status.is_ok()) {
            if let Some(q) = base.iter().find(|q| q.device == x.device && q.scene == x.scene && q.rays == x.rays) {
                let r = x.mrays_median / q.mrays_median;
                md += &format!(
                    "| {} | {} | {} | {} | {:.2} | {r:.3} |\n",
                    x.device, x.scene, x.rays, x.kernel, x.mrays_median
                );
            }
        }
        md += "\n";
    }
    md
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

/// The headline ratios of one device's sweep (the device report's summary): every layout and
/// math mode ÷ f32 at B = 4 and 8 (P = 1), f32's packet series ÷ P = 1 at B = 4, and f32 ÷
/// each baseline; Mrays/s, means over the scenes and ray kinds measured on both sides.
pub fn device_headline(rows: &[Row]) -> String {
    let mut md = String::new();
    let devices: Vec<&str> = {
        let mut d: Vec<&str> = rows.iter().map(|r| r.device.as_str()).collect();
        d.sort();
        d.dedup();
        d
    };
    let points = layout_points(rows);
    let mean = |v: &[f64]| if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 };
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status.is_ok() && r.mrays_median > 0.0).collect();
    for dev in devices {
        let mut labels: Vec<(usize, String)> =
            points.keys().filter(|(d, _, l, _)| d == dev && l != "f32").map(|(_, o, l, _)| (*o, l.clone())).collect();
        labels.dedup();
        if !labels.is_empty() {
            md += &format!("Mrays/s ÷ f32 on {dev} (above 1: faster than f32; means over scenes and ray kinds):\n\n");
            md += &header(&[("layout", false), ("B = 4", true), ("B = 8", true)]);
        }
        for (o, l) in &labels {
            let at = |b: usize| {
                points.get(&(dev.to_string(), *o, l.clone(), b)).map_or(f64::NAN, |p| p.ratio[0] / p.n as f64)
            };
            md += &format!("| {l} | {} | {} |\n", fmt(at(4)), fmt(at(8)));
        }
        // f32's packets at B = 4: each P ÷ P = 1 for the same scene and rays.
        let f32_at = |p: usize, s: &str, r: &str| {
            ok.iter().find(|x| {
                x.device == dev
                    && x.layout == "f32"
                    && x.branching == 4
                    && x.packet == p
                    && x.scene == s
                    && x.rays == r
                    && x.kernel.starts_with("trav_")
            })
        };
        let singles: Vec<&&Row> =
            ok.iter().filter(|x| x.device == dev && x.layout == "f32" && x.branching == 4 && x.packet == 1).collect();
        let mut packets: Vec<usize> =
            ok.iter().filter(|x| x.device == dev && x.layout == "f32" && x.packet > 1).map(|x| x.packet).collect();
        packets.sort();
        packets.dedup();
        if !packets.is_empty() {
            md += "\nf32 at B = 4, packets of P rays ÷ single rays (P = 1):\n\n";
            let titles: Vec<String> = packets.iter().map(|p| format!("P = {p}")).collect();
            md += &header(&titles.iter().map(|t| (t.as_str(), true)).collect::<Vec<_>>());
            let cells: Vec<String> = packets
                .iter()
                .map(|&p| {
                    let v: Vec<f64> = singles
                        .iter()
                        .filter_map(|s| f32_at(p, &s.scene, &s.rays).map(|x| x.mrays_median / s.mrays_median))
                        .collect();
                    fmt(mean(&v))
                })
                .collect();
            md += &format!("| {} |\n", cells.join(" | "));
        }
        let mut base = Vec::new();
        for b in BaselineId::all() {
            let v: Vec<f64> = singles
                .iter()
                .filter_map(|s| {
                    ok.iter()
                        .find(|q| q.device == dev && q.layout == b.name() && q.scene == s.scene && q.rays == s.rays)
                        .map(|q| s.mrays_median / q.mrays_median)
                })
                .collect();
            if !v.is_empty() {
                base.push(format!("f32 (B = 4) ÷ `{b}` {}", fmt(mean(&v))));
            }
        }
        if !base.is_empty() {
            md += &format!("\n{} (above 1: our f32 kernel is faster).\n", base.join("; "));
        }
        md += "\n";
    }
    md
}
