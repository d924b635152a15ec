//! Each baseline (the driver's ray queries, Embree) against every variant.

use super::*;

/// One table per baseline with rows: every variant's Mrays/s ÷ the baseline's on the same
/// device, scene and rays.
pub fn against_baselines(rows: &[Row]) -> String {
    let mut md = String::new();
    for b in BaselineId::all() {
        let base: Vec<&Row> =
            rows.iter().filter(|r| r.what == crate::report::What::Baseline(b) && r.status.is_ok()).collect();
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
