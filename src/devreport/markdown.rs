//! The device report's `report.md`: the device, the steps, the headline ratios and each
//! step's own report as a section.

use super::*;

/// "N ok, N failed, N skipped" from a conformance.csv.
pub(super) fn conformance_counts(csv: &Path) -> Option<String> {
    let mut r = csv::Reader::from_path(csv).ok()?;
    let col = r.headers().ok()?.iter().position(|h| h == "status")?;
    let (mut ok, mut failed, mut skipped) = (0, 0, 0);
    for rec in r.records().flatten() {
        let s = rec.get(col).unwrap_or("");
        if s == "ok" {
            ok += 1;
        } else if s.starts_with("skipped") {
            skipped += 1;
        } else {
            failed += 1;
        }
    }
    Some(format!("{ok} ok, {failed} failed, {skipped} skipped"))
}

/// The folder's `report.md`.
pub(super) fn markdown(
    state: &State,
    dev: &DeviceInfo,
    rows: &[Row],
    out: &Path,
    jobs: usize,
    big: Option<&str>,
) -> String {
    let total: f64 = state.runs.iter().map(|r| r.seconds).sum();
    let runs: Vec<String> =
        state.runs.iter().map(|r| format!("{:.0} s of a {:.0} s budget", r.seconds, r.budget_s)).collect();
    let mut md = format!(
        "# halftrace device report: {}\n\n\
         - device: {} ({}), Vulkan {}\n- driver: {}\n- halftrace {} ({})\n- scenes: {}; rays at {}×{}\n\
         - made by `halftrace device-report` in {} run(s): {} ({total:.0} s in all)\n\n",
        state.device,
        state.device,
        state.kind,
        state.api_version,
        state.driver,
        state.version,
        state.commit,
        state.scenes.join(", "),
        state.width,
        state.height,
        state.runs.len(),
        runs.join("; "),
    );
    if let Some(b) = big {
        md.insert_str(md.len() - 1, &format!("- {b}\n"));
    }
    md += &format!(
        "fp16 {}, 16-bit storage {}, subgroup size {}, ray queries {}, ray-tracing pipeline {}, pipeline statistics \
         {}.\n\n",
        dev.shader_float16,
        dev.storage_16bit,
        dev.subgroup_size,
        dev.ray_query,
        dev.ray_tracing_pipeline,
        dev.pipeline_statistics
    );
    md += "## Steps\n\n| step | status | seconds | output |\n|---|---|---:|---|\n";
    for name in STEPS {
        match state.steps.get(*name) {
            Some(s) => {
                let link = if out.join(&s.output).is_file() { format!("[{0}]({0})", s.output) } else { "–".into() };
                md += &format!("| {name} | {} | {:.0} | {link} |\n", s.status, s.seconds);
            }
            None => md += &format!("| {name} | not run | – | – |\n"),
        }
    }
    md += "\n";
    if !rows.is_empty() {
        md += &format!(
            "## Headline ({} of {jobs} sweep jobs; every variant validated against its CPU reference before it was \
             timed)\n\n",
            rows.len()
        );
        md += &report::tables::device_headline(rows);
        md += "Every table and plot: [sweep/report.md](sweep/report.md).\n\n";
    }
    if let Ok(b) = std::fs::read_to_string(out.join("bench.md")) {
        md += "## Bench (short: 3 rounds of 3 timed dispatches)\n\n";
        md += &demote(&b);
        md += "\n";
    }
    md += "## Merging\n\n`halftrace report reports/<device> [reports/<other device>…] --out reports/merged` puts \
           several devices' sweeps in one report.\n";
    md
}

/// A Markdown document's headings one level lower (it becomes a section of another).
pub(super) fn demote(md: &str) -> String {
    md.lines().map(|l| if l.starts_with('#') { format!("##{l}\n") } else { format!("{l}\n") }).collect()
}
