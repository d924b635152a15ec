//! Compilers releases side by side (`isa --compilers pinned,newest`): a device built on more
//! than one Mesa release gets one column per release in every table, and isa.md a section of
//! what the release changes — each kernel's figures per release and its verdict against the
//! same release's f32, marked where the releases disagree.

use super::{sorted, IsaRow};
use crate::report::key::f32_peer;
use crate::report::rows::order;

/// The compiler release a row's driver names: `Mesa 26.2.6` from `radv Mesa 26.2.6-1` (the
/// upstream version: a distribution's suffix dropped, so that Debian's build of 25.0.7 and the
/// pinned one are one release), else the driver string as it is.
pub fn release(driver: &str) -> String {
    let mut found = None;
    let mut rest = driver;
    while let Some(i) = rest.find("Mesa ") {
        let after = &rest[i + 5..];
        if after.starts_with(|c: char| c.is_ascii_digit()) {
            let v = after.split_whitespace().next().unwrap_or("");
            found = Some(v.split('-').next().unwrap_or(v).to_string());
        }
        rest = after;
    }
    found.map(|v| format!("Mesa {v}")).unwrap_or_else(|| driver.to_string())
}

/// The releases of `rows`, oldest first (by their version numbers).
fn releases(rows: &[&IsaRow]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        let rel = release(&r.driver);
        if !out.contains(&rel) {
            out.push(rel);
        }
    }
    out.sort_by_key(|s| version(s));
    out
}

/// A release's version numbers, for ordering releases (`Mesa 26.2.6` → 26, 2, 6).
pub fn version(release: &str) -> Vec<u64> {
    release.split(|c: char| !c.is_ascii_digit()).filter(|p| !p.is_empty()).filter_map(|p| p.parse().ok()).collect()
}

/// Each row's name in the tables: its device label, and its release where `rows` hold that
/// device on more than one release (so that the releases stand side by side as two devices).
pub fn labeller(rows: &[IsaRow]) -> impl Fn(&IsaRow) -> String {
    let mut multi: Vec<String> = Vec::new();
    let mut seen: Vec<(String, String)> = Vec::new();
    for r in rows {
        let (d, rel) = (r.device_label(), release(&r.driver));
        if seen.iter().any(|(sd, sr)| *sd == d && *sr != rel) && !multi.contains(&d) {
            multi.push(d.clone());
        }
        seen.push((d, rel));
    }
    move |r: &IsaRow| {
        let d = r.device_label();
        if multi.contains(&d) {
            format!("{d} · {}", release(&r.driver))
        } else {
            d
        }
    }
}

/// A kernel's verdict against its f32 on the same device and release: whether it keeps f32's
/// occupancy (registers per thread where the driver reports no occupancy).
fn verdict(r: &IsaRow, all: &[IsaRow]) -> Option<String> {
    let f = f32_peer(r, all.iter())?;
    match (r.occupancy, f.occupancy, r.registers, f.registers) {
        (Some(o), Some(fo), ..) if fo > 0.0 => Some(if o >= fo {
            "keeps f32's occupancy".to_string()
        } else {
            format!("loses occupancy (×{:.2})", o / fo)
        }),
        (_, _, Some(g), Some(fg)) if fg > 0.0 => Some(if g <= fg {
            "no more registers than f32".to_string()
        } else {
            format!("more registers (×{:.2})", g / fg)
        }),
        _ => None,
    }
}

/// The verdict's class: what a change of release is judged on (the ratio may move within it).
fn class(v: &str) -> &str {
    v.split(" (").next().unwrap_or(v)
}

fn cell(r: Option<&IsaRow>) -> String {
    let n = |x: Option<f64>| x.map(|v| format!("{v:.0}")).unwrap_or_else(|| "–".into());
    match r {
        Some(r) if r.status.is_ok() => {
            format!("{} / {} / {} / {}", n(r.registers), n(r.occupancy), n(r.spills), n(r.cycles))
        }
        Some(r) if r.status.is_skipped() => "skipped".into(),
        Some(_) => "failed".into(),
        None => "–".into(),
    }
}

/// isa.md's section on what the compilers release changes: "" unless some device was built on
/// more than one release. Per device and kernel at P = 1 (B = 4, and any other B whose verdict
/// the release changes): registers per thread / occupancy / spills and fills / the compiler's
/// cycles on each release, each release's verdict against its own f32, **changed** where the
/// verdicts' classes differ; then each device's best reduced-precision kernel per release.
pub fn section(rows: &[IsaRow], h: &str) -> String {
    let rows = sorted(rows);
    // Devices with rows on two releases or more, in report order.
    let mut devices: Vec<String> = Vec::new();
    for r in &rows {
        let d = r.device_label();
        if !devices.contains(&d)
            && rows.iter().any(|o| o.device_label() == d && release(&o.driver) != release(&r.driver))
        {
            devices.push(d);
        }
    }
    if devices.is_empty() {
        return String::new();
    }
    // The releases those devices were built on (a device on one release only adds none).
    let theirs: Vec<&IsaRow> = rows.iter().filter(|r| devices.contains(&r.device_label())).collect();
    let rels = releases(&theirs);
    let mut md = format!(
        "{h}# What the compilers release changes (P = 1)\n\nEach device built on more than one release: registers per \
         thread / occupancy / spills and fills / the compiler's cycles, per release, and each kernel's verdict against \
         the same release's f32 — whether it keeps f32's occupancy (registers, where the driver reports no occupancy). \
         **changed**: the releases' verdicts differ. B = 4, and any other B where a verdict changes.\n\n\
         | device | kernel | B | {} | verdict |\n|---|---|---|{}---|\n",
        rels.join(" | "),
        "---|".repeat(rels.len())
    );
    let mut best = String::new();
    let mut changes = 0;
    for d in &devices {
        let here: Vec<&IsaRow> = rows.iter().filter(|r| r.device_label() == *d && r.packet == 1).collect();
        let mut kernels: Vec<(usize, String, usize)> = Vec::new();
        for r in &here {
            let k = (order(&r.layout), r.label(), r.branching);
            if !kernels.contains(&k) {
                kernels.push(k);
            }
        }
        kernels.sort();
        let of = |rel: &str, label: &str, b: usize| {
            here.iter().copied().find(|r| release(&r.driver) == rel && r.label() == label && r.branching == b)
        };
        for (_, label, b) in &kernels {
            let verdicts: Vec<Option<String>> = rels
                .iter()
                .map(|rel| of(rel, label, *b).filter(|r| r.status.is_ok()).and_then(|r| verdict(r, &rows)))
                .collect();
            let known: Vec<&String> = verdicts.iter().flatten().collect();
            let changed = known.windows(2).any(|w| class(w[0]) != class(w[1]));
            if *b != 4 && !changed {
                continue;
            }
            changes += changed as usize;
            let cells: Vec<String> = rels.iter().map(|rel| cell(of(rel, label, *b))).collect();
            let v = if label == "f32" {
                "–".to_string()
            } else {
                verdicts.iter().map(|v| v.clone().unwrap_or_else(|| "–".into())).collect::<Vec<_>>().join(" → ")
            };
            md += &format!(
                "| {d} | {label} | {b} | {} | {v}{} |\n",
                cells.join(" | "),
                if changed { " **changed**" } else { "" }
            );
        }
        // The best reduced-precision kernel per release at B = 4: most occupancy, then fewest
        // registers, spills and fills, cycles, instructions.
        let bests: Vec<String> = rels
            .iter()
            .map(|rel| {
                here.iter()
                    .filter(|r| release(&r.driver) == *rel && r.status.is_ok() && r.branching == 4 && r.layout != "f32")
                    .min_by(|a, b| {
                        let k = |r: &IsaRow| {
                            let last = |x: Option<f64>| x.unwrap_or(f64::MAX);
                            (
                                -r.occupancy.unwrap_or(0.0),
                                last(r.registers),
                                last(r.spills),
                                last(r.cycles),
                                last(r.instructions),
                            )
                        };
                        k(a).partial_cmp(&k(b)).unwrap_or(std::cmp::Ordering::Equal)
                    })
                    .map(|r| r.label())
                    .unwrap_or_else(|| "–".into())
            })
            .collect();
        let known: Vec<&String> = bests.iter().filter(|b| *b != "–").collect();
        let differ = known.windows(2).any(|w| w[0] != w[1]);
        best += &format!("| {d} | {}{} |\n", bests.join(" | "), if differ { " **changed**" } else { "" });
    }
    md += &format!(
        "\n{changes} kernel verdict(s) changed by the release.\n\nThe best reduced-precision kernel at B = 4, P = 1 \
         (most occupancy, then fewest registers, spills and fills, cycles, instructions), per release:\n\n| device | {} |\n|---|{}\n{best}\n",
        rels.join(" | "),
        "---|".repeat(rels.len())
    );
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    /// navi31's `layout` at B = 4, P = 1 on a release: a null device on 25.0.7, the amdgpu
    /// shim's device on 26.2.6.
    fn row(layout: &str, newest: bool, registers: f64, occupancy: f64) -> IsaRow {
        let (device, driver) = if newest {
            ("AMD Radeon RX 7900 XTX (RADV NAVI31) (amdgpu shim)", "radv Mesa 26.2.6-1")
        } else {
            ("Null hardware (RADV NAVI31)", "radv Mesa 25.0.7-2~bpo12+1")
        };
        IsaRow {
            registers: Some(registers),
            occupancy: Some(occupancy),
            spills: Some(10.0),
            ..super::super::test_row(layout, (device, "navi31", "RDNA3", driver))
        }
        .typed()
    }

    /// One device on two releases: one column each, in version order whatever the rows' order;
    /// a kernel that keeps f32's occupancy on one release and loses it on the other is marked,
    /// one whose verdict holds is not; the best kernel per release; the tables name each
    /// release's device apart. One release only: no section.
    #[test]
    fn a_release_that_changes_a_verdict_is_marked() {
        let mut rows = vec![
            row("f32", true, 60.0, 24.0),
            row("f16w", true, 72.0, 20.0),
            row("q8", true, 60.0, 24.0),
            row("f32", false, 60.0, 24.0),
            row("f16w", false, 60.0, 24.0),
            row("q8", false, 60.0, 24.0),
        ];
        crate::report::isa::set_ratios(&mut rows);
        let md = section(&rows, "##");
        assert!(md.contains("| device | kernel | B | Mesa 25.0.7 | Mesa 26.2.6 | verdict |"), "{md}");
        let f16w = md.lines().find(|l| l.contains("| f16w f32 |")).unwrap_or_else(|| panic!("{md}"));
        assert!(
            f16w.contains(
                "| 60 / 24 / 10 / – | 72 / 20 / 10 / – | keeps f32's occupancy → loses occupancy (×0.83) **changed** |"
            ),
            "{f16w}"
        );
        let q8 = md.lines().find(|l| l.contains("| q8 f32 |")).unwrap();
        assert!(q8.ends_with("keeps f32's occupancy → keeps f32's occupancy |"), "{q8}");
        assert!(md.contains("1 kernel verdict(s) changed"), "{md}");
        assert!(md.contains("| navi31 (RDNA3) | f16w f32 | q8 f32 **changed** |"), "{md}");
        let lab = labeller(&rows);
        assert_eq!(
            (lab(&rows[0]), lab(&rows[3])),
            ("navi31 (RDNA3) · Mesa 26.2.6".into(), "navi31 (RDNA3) · Mesa 25.0.7".into())
        );
        // A device on one release of its own (a real GPU's driver) adds no column.
        let mut other = row("f32", false, 60.0, 24.0);
        (other.device, other.family, other.driver) = ("Some GPU".into(), String::new(), "NVIDIA 580.95.05".into());
        let mut with_other = rows.clone();
        with_other.push(other);
        let md2 = section(&with_other, "##");
        assert!(md2.contains("| Mesa 25.0.7 | Mesa 26.2.6 | verdict |") && !md2.contains("NVIDIA"), "{md2}");
        let one: Vec<IsaRow> = rows.iter().filter(|r| r.driver.contains("26.2")).cloned().collect();
        assert_eq!(section(&one, "##"), "");
        assert_eq!(labeller(&one)(&one[0]), "navi31 (RDNA3)");
    }

    #[test]
    fn a_release_is_the_upstream_mesa_version() {
        assert_eq!(release("radv Mesa 25.0.7-2~bpo12+1"), "Mesa 25.0.7");
        assert_eq!(release("turnip Mesa driver Mesa 26.2.6-1"), "Mesa 26.2.6");
        assert_eq!(release("V3DV Mesa Mesa 25.0.7"), "Mesa 25.0.7");
        assert_eq!(release("NVIDIA 580.95.05"), "NVIDIA 580.95.05");
    }
}
