//! The report's plots, each as PNG and SVG: f16h ÷ f32 by B and by P, Mrays/s per variant,
//! node memory per layout, and every layout ÷ f32 by B.

use super::rows::{layouts_in, Row};
use super::tables::{layout_label, LayoutPoint};
use crate::layout::LayoutId;
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Mrays/s ÷ f32 against B, one line per (device,) layout.
pub fn layouts_plot(points: &BTreeMap<(String, usize, String, usize), LayoutPoint>, out: &Path) -> anyhow::Result<()> {
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
        "layouts",
        "Mrays/s of each layout / f32 by branching factor (P = 1)",
        "branching factor B",
        "Mrays/s / f32",
        &lines,
    )
}

fn font() -> anyhow::Result<()> {
    use std::sync::OnceLock;
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        // HALFTRACE_FONT, then fonts/ beside the binary (a bundle, scripts/bundle.sh), then
        // the distributions' places.
        let mut candidates: Vec<std::path::PathBuf> = Vec::new();
        candidates.extend(std::env::var_os("HALFTRACE_FONT").map(Into::into));
        if let Some(dir) = std::env::current_exe().ok().and_then(|e| e.parent().map(|d| d.to_path_buf())) {
            candidates.push(dir.join("fonts/DejaVuSans.ttf"));
        }
        for c in [
            "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
            "/usr/share/fonts/TTF/DejaVuSans.ttf",
            "/usr/share/fonts/dejavu/DejaVuSans.ttf",
        ] {
            candidates.push(c.into());
        }
        for c in &candidates {
            if let Ok(b) = std::fs::read(c) {
                let leaked: &'static [u8] = Box::leak(b.into_boxed_slice());
                return plotters::style::register_font("sans-serif", FontStyle::Normal, leaked)
                    .map_err(|_| format!("{}: not a usable font", c.display()));
            }
        }
        Err("no DejaVuSans.ttf found for plot labels (install fonts-dejavu-core: scripts/install-deps.sh, or name \
             one with HALFTRACE_FONT)"
            .into())
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
    // Up to three panels a row.
    let cols = panels.len().clamp(1, 3);
    let grid = (panels.len().max(1).div_ceil(cols), cols);
    let (width, height) = (520 * cols as u32 + 80, 520 * grid.0 as u32);
    macro_rules! draw {
        ($root:expr) => {{
            let root = $root;
            root.fill(&WHITE)?;
            let root = root.titled(title, ("sans-serif", 22))?;
            let areas = root.split_evenly(grid);
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
        draw!(BitMapBackend::new(png, (width, height)).into_drawing_area());
        Ok(())
    })?;
    crate::fsx::with_temp(&out.join(format!("{name}.svg")), |svg| {
        draw!(SVGBackend::new(svg, (width, height)).into_drawing_area());
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

/// Named lines of (x, y) points.
pub type Lines = Vec<(String, Vec<(usize, f64)>)>;

/// Panels of plain lines, each (caption, lines), three a row.
pub fn panels(
    out: &Path,
    name: &str,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    panels: &[(String, Lines)],
) -> anyhow::Result<()> {
    let panels: Vec<Panel> = panels
        .iter()
        .map(|(caption, lines)| Panel {
            caption: caption.clone(),
            xlabel: xlabel.into(),
            lines: lines.iter().map(|(l, p)| Line { label: l.clone(), pts: p.clone(), bars: Vec::new() }).collect(),
        })
        .collect();
    chart(out, name, title, ylabel, &panels)
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

pub fn plots(rows: &[Row], by_b: &Series, by_p: &Series, out: &Path) -> anyhow::Result<()> {
    let ratio = format!("{} / {}", LayoutId::poster().0, LayoutId::f32());
    line_chart(
        out,
        "ratio_vs_b",
        &format!("{ratio} by branching factor (P = 1)"),
        "branching factor B",
        &ratio,
        &ratio_lines(by_b),
    )?;
    line_chart(
        out,
        "ratio_vs_p",
        &format!("{ratio} by packet size (B = 4)"),
        "packet size P",
        &ratio,
        &ratio_lines(by_p),
    )?;
    // Mrays/s per variant: one panel per series (by B at P = 1, by P at the packet B), one
    // line per layout/math (mean over scenes and ray kinds), min–max bars over the timed
    // dispatches (means of the per-row minima and maxima).
    let ok: Vec<&Row> = rows.iter().filter(|r| r.status.is_ok()).collect();
    let pb = ok.iter().filter(|r| r.packet > 1).map(|r| r.branching).next().unwrap_or(4);
    let mut by_b_lines = Vec::new();
    let mut by_p_lines = Vec::new();
    let mut labels: Vec<String> = Vec::new();
    for r in ok.iter().filter(|r| r.what.builtin().is_some()) {
        let l = layout_label(r);
        if !labels.contains(&l) {
            labels.push(l);
        }
    }
    for label in &labels {
        let mean = |f: &dyn Fn(&Row) -> bool, key: &dyn Fn(&Row) -> usize| -> Line {
            let mut m: BTreeMap<usize, ([f64; 3], usize)> = BTreeMap::new();
            for r in ok.iter().filter(|r| layout_label(r) == *label && r.what.builtin().is_some() && f(r)) {
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
    for layout in layouts_in(&ok) {
        let mut m: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
        for r in ok.iter().filter(|r| r.layout == layout && r.packet == 1) {
            let e = m.entry(r.branching).or_insert((0.0, 0));
            e.0 += r.bvh_bytes as f64 / 1024.0;
            e.1 += 1;
        }
        let pts: Vec<(usize, f64)> = m.into_iter().map(|(k, (s, n))| (k, s / n as f64)).collect();
        lines.push((format!("{layout} node bytes (KiB)"), pts));
    }
    line_chart(
        out,
        "memory",
        "BVH node memory per layout and B (mean over scenes)",
        "branching factor B",
        "KiB",
        &lines,
    )
}
