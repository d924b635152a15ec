//! The headline ratios (every layout and math ÷ f32, by B and by P), storage against
//! arithmetic, and the device report's headline.

use super::*;
use crate::precision::Math;
use crate::report::key::{f32_peer, What};

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
    for h in ok.iter().filter(|r| r.what.is_poster()) {
        if let Some(f) = f32_peer(*h, ok.iter().copied()) {
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
    let (poster, _) = LayoutId::poster();
    let label = |r: &Row| match r.what.builtin() {
        Some(k) if r.what.is_f32() => k.variant.layout.name().to_string(),
        Some(k) => format!("{}/{}", k.variant.layout, k.variant.math.name()),
        None => String::new(),
    };
    for h in ok.iter().filter(|r| r.what.layout() == Some(poster) && r.what.builtin().is_some()) {
        if let Some(f) = f32_peer(*h, ok.iter().copied()) {
            let e = acc
                .entry((h.device.clone(), h.branching, h.packet))
                .or_default()
                .entry(h.math.clone())
                .or_insert((0.0, 0));
            e.0 += h.mrays_median / f.mrays_median;
            e.1 += 1;
            for r in [*h, f] {
                let k = (r.device.clone(), r.branching, r.packet, label(r));
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
    let f32_name = LayoutId::f32().name();
    let vs = |m: Math| format!("{} ÷ {f32_name}", m.name());
    let (bytes_f32, of16, of32) = (
        format!("node bytes/ray {f32_name}"),
        format!("{poster}/{}", Math::F16.name()),
        format!("{poster}/{}", Math::F32.name()),
    );
    let (v16, v32, vmix) = (vs(Math::F16), vs(Math::F32), vs(Math::Mixed));
    md += &header(&[
        ("device", false),
        ("B", true),
        ("P", true),
        (&v16, true),
        (&v32, true),
        (&vmix, true),
        (&bytes_f32, true),
        (&of16, true),
        (&of32, true),
        ("raw fp16:fp32", true),
    ]);
    for ((d, b, p), m) in &acc {
        let get = |k: Math| m.get(k.name()).map(|(s, n)| fmt(s / *n as f64)).unwrap_or_else(|| "–".into());
        let by = |k: String| {
            bytes
                .get(&(d.clone(), *b, *p, k))
                .map(|(s, n)| format!("{:.0}", s / *n as f64))
                .unwrap_or_else(|| "–".into())
        };
        md += &format!(
            "| {d} | {b} | {p} | {} | {} | {} | {} | {} | {} | {} |\n",
            get(Math::F16),
            get(Math::F32),
            get(Math::Mixed),
            by(f32_name.into()),
            by(of16.clone()),
            by(of32.clone()),
            fmt(raw[d])
        );
    }
    md + "\n"
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
    let f32_name = LayoutId::f32().name();
    for dev in devices {
        let mut labels: Vec<(usize, String)> = points
            .keys()
            .filter(|(d, _, l, _)| d == dev && l != f32_name)
            .map(|(_, o, l, _)| (*o, l.clone()))
            .collect();
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
                x.device == dev && x.what.is_f32() && x.branching == 4 && x.packet == p && x.scene == s && x.rays == r
            })
        };
        let singles: Vec<&&Row> =
            ok.iter().filter(|x| x.device == dev && x.what.is_f32() && x.branching == 4 && x.packet == 1).collect();
        let mut packets: Vec<usize> =
            ok.iter().filter(|x| x.device == dev && x.what.is_f32() && x.packet > 1).map(|x| x.packet).collect();
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
                        .find(|q| {
                            q.device == dev && q.what == What::Baseline(b) && q.scene == s.scene && q.rays == s.rays
                        })
                        .map(|q| s.mrays_median / q.mrays_median)
                })
                .collect();
            if !v.is_empty() {
                base.push(format!("{f32_name} (B = 4) ÷ `{b}` {}", fmt(mean(&v))));
            }
        }
        if !base.is_empty() {
            md += &format!("\n{} (above 1: our f32 kernel is faster).\n", base.join("; "));
        }
        md += "\n";
    }
    md
}
