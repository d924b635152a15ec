//! AMD's compiler without AMD hardware: RADV opens a *null device* for the GPU family named
//! in `RADV_FORCE_FAMILY` — pipelines build with ACO, AMD's production shader compiler, and
//! their statistics and disassembly can be read; nothing can run. [`FAMILIES`] are the family
//! names Mesa knows (amd_family.c); `crate::isa::known_families` tells which the installed RADV
//! opens (a name it does not know aborts the process inside RADV, so only known names are
//! opened here).

use super::{list_devices, ContextOptions, DeviceInfo, Gpu, GpuError};

/// A GPU family: the name `RADV_FORCE_FAMILY` takes and its generation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Family {
    pub name: &'static str,
    pub generation: &'static str,
}

const fn f(name: &'static str, generation: &'static str) -> Family {
    Family { name, generation }
}

/// Every family name of Mesa's `ac_get_family_name` (GFX6 on), oldest first.
pub const FAMILIES: &[Family] = &[
    f("tahiti", "GCN1"),
    f("pitcairn", "GCN1"),
    f("verde", "GCN1"),
    f("oland", "GCN1"),
    f("hainan", "GCN1"),
    f("bonaire", "GCN2"),
    f("kabini", "GCN2"),
    f("kaveri", "GCN2"),
    f("hawaii", "GCN2"),
    f("tonga", "GCN3"),
    f("iceland", "GCN3"),
    f("carrizo", "GCN3"),
    f("fiji", "GCN3"),
    f("stoney", "GCN3"),
    f("polaris10", "GCN4"),
    f("polaris11", "GCN4"),
    f("polaris12", "GCN4"),
    f("vegam", "GCN4"),
    f("vega10", "GCN5"),
    f("vega12", "GCN5"),
    f("vega20", "GCN5"),
    f("raven", "GCN5"),
    f("raven2", "GCN5"),
    f("renoir", "GCN5"),
    f("mi100", "CDNA1"),
    f("mi200", "CDNA2"),
    f("gfx940", "CDNA3"),
    f("navi10", "RDNA1"),
    f("navi12", "RDNA1"),
    f("navi14", "RDNA1"),
    f("navi21", "RDNA2"),
    f("navi22", "RDNA2"),
    f("navi23", "RDNA2"),
    f("vangogh", "RDNA2"),
    f("navi24", "RDNA2"),
    f("rembrandt", "RDNA2"),
    f("raphael_mendocino", "RDNA2"),
    f("navi31", "RDNA3"),
    f("navi32", "RDNA3"),
    f("navi33", "RDNA3"),
    f("gfx1103_r1", "RDNA3"),
    f("gfx1103_r2", "RDNA3"),
    f("gfx1150", "RDNA3.5"),
    f("gfx1151", "RDNA3.5"),
    f("gfx1152", "RDNA3.5"),
    f("gfx1153", "RDNA3.5"),
    f("gfx1200", "RDNA4"),
    f("gfx1201", "RDNA4"),
];

/// The families `isa` builds for without `--family`: one per generation from GCN4 to RDNA4
/// (those the installed RADV opens).
pub const DEFAULT_FAMILIES: &[&str] = &["polaris10", "vega10", "navi10", "navi21", "navi31", "gfx1201"];

/// The family of a name (case-insensitive), if Mesa has one by that name.
pub fn family(name: &str) -> Option<Family> {
    FAMILIES.iter().copied().find(|f| f.name.eq_ignore_ascii_case(name))
}

/// The family of a device's name ("Null hardware (RADV NAVI31)" → navi31), for any RADV
/// device named after its family.
pub fn family_of(device: &str) -> Option<Family> {
    let up = device.to_uppercase();
    FAMILIES.iter().copied().find(|f| up.contains(&format!("RADV {})", f.name.to_uppercase())))
}

/// Runs `f` with `RADV_FORCE_FAMILY=name` (RADV reads it when an instance enumerates its
/// devices), then puts the variable back as it was. Changing the environment is sound only
/// while no other thread reads it: `isa` opens its devices from its one thread.
fn with_family<T>(name: &str, f: impl FnOnce() -> T) -> T {
    let old = std::env::var_os("RADV_FORCE_FAMILY");
    std::env::set_var("RADV_FORCE_FAMILY", name);
    let r = f();
    match old {
        Some(v) => std::env::set_var("RADV_FORCE_FAMILY", v),
        None => std::env::remove_var("RADV_FORCE_FAMILY"),
    }
    r
}

/// The null device of `fam` among the devices listed with it forced.
fn null_device(fam: Family, devices: &[DeviceInfo]) -> Option<&DeviceInfo> {
    devices.iter().find(|d| d.compile_only && family_of(&d.name) == Some(fam))
}

/// The names of the null devices listed with `RADV_FORCE_FAMILY` as the environment has it
/// (what `halftrace probe-family` prints for its parent). An unknown family aborts inside
/// RADV, which is why [`crate::isa::known_families`] asks a child process.
pub fn listed() -> Result<Vec<String>, GpuError> {
    Ok(list_devices()?.into_iter().filter(|d| d.compile_only).map(|d| d.name).collect())
}

/// Opens the null device of family `name` to read its compiler's statistics.
pub fn open(name: &str, validation: bool) -> Result<Gpu, GpuError> {
    let fam = family(name).ok_or_else(|| {
        let all: Vec<&str> = FAMILIES.iter().map(|f| f.name).collect();
        GpuError::Other(format!("--family '{name}': Mesa has no such GPU family (one of: {})", all.join(", ")))
    })?;
    with_family(fam.name, || {
        let devices = list_devices()?;
        let d = null_device(fam, &devices).ok_or_else(|| {
            if let Some(kernel) = super::device::shim() {
                return GpuError::Other(format!(
                    "--family {}: the {kernel} shim opens no device for it (AMDGPU_GPU_ID={}; the shim knows fewer \
                     families than Mesa)",
                    fam.name,
                    std::env::var("AMDGPU_GPU_ID").unwrap_or_default()
                ));
            }
            GpuError::Other(format!(
                "--family {}: the installed RADV opens no null device for it (is RADV — Debian's mesa-vulkan-drivers — \
                 installed, and does this Mesa know the family? `halftrace devices` lists those it does)",
                fam.name
            ))
        })?;
        let opts =
            ContextOptions { device: Some(d.index.to_string()), validation, statistics: true, ..Default::default() };
        Gpu::new(&opts)
    })
}
