//! What halftrace knows of each GPU vendor, one file each (`src/vendor/<name>.rs`) and one line
//! in the [`vendors!`] list below: which Vulkan drivers compile for it, its compiler under
//! Mesa's drm-shim and the models that shim fakes, how its compiler's statistics map to the
//! vendor-neutral columns (and where each comes from, for `docs/vendors.md`), what its cycle
//! figure assumes, which disassembly it prints, and its device quirks — set once from the
//! driver id after `gpu::device` has read the device (wgpu-hal's `Workarounds` are the model).
//! Nothing else names a vendor: the compiler view, `estimate` and the tables read the
//! registry, so a new vendor is one file, one line here, and its stanza in
//! `scripts/install-compilers.sh`.

use ash::vk;
use std::collections::BTreeMap;

/// Declares each vendor's module and lists it in [`REGISTRY`], in table order.
macro_rules! vendors {
    ($($(#[$m:meta])* $module:ident :: $vendor:ident),* $(,)?) => {
        $($(#[$m])* pub mod $module;)*
        /// Every vendor, in table order.
        pub static REGISTRY: &[&Vendor] = &[$($(#[$m])* &$module::$vendor),*];
    };
}

vendors! {
    amd::AMD,
    qualcomm::QUALCOMM,
    arm::ARM,
    intel::INTEL,
    nvidia::NVIDIA,
    broadcom::BROADCOM,
    apple::APPLE,
    // A vendor no GPU has: the test that a vendor is one file and this one line.
    #[cfg(test)]
    fake::FAKE,
}

/// One GPU vendor: everything halftrace knows of it.
pub struct Vendor {
    /// Its name in rows (`isa.csv`'s `vendor` column), tables and docs.
    pub name: &'static str,
    /// The Vulkan drivers (`VkDriverId`) that compile for it.
    pub driver_ids: &'static [vk::DriverId],
    /// Lower-case pieces of a driver's name (`driverName driverInfo`) that mark it: rows read
    /// from files carry the name, not the id.
    pub driver_names: &'static [&'static str],
    /// Its compiler opened under a drm-shim; `None` where it has none (AMD's families open as
    /// RADV's null device where the release still has one, `gpu::null`).
    pub shim: Option<Shim>,
    /// The GPU models its shim fakes, in table order (`--family` names).
    pub models: &'static [Model],
    /// Whose statistic names its driver reports, which picks its tables.
    pub stats: Stats,
    /// Where each vendor-neutral column comes from, in [`COLUMNS`] order (docs/vendors.md).
    pub sources: [&'static str; 6],
    /// The vendor-neutral columns from the driver's statistics.
    pub neutral: fn(&Input) -> Neutral,
    /// The disassembly its driver prints (a representation named `…assembly…`).
    pub disassembly: Option<Disassembly>,
    /// Its occupancy unit; `None` where the driver does not report one.
    pub occupancy: Option<Occupancy>,
    /// What its compiler's whole-shader cycle figure assumes.
    pub cycles: &'static str,
    /// Its devices' quirks.
    pub quirks: Quirks,
}

/// A driver under Mesa's drm-shim: `lib<kernel>_noop_drm_shim.so` fakes the kernel driver.
#[derive(Clone, Copy, Debug)]
pub struct Shim {
    /// The kernel driver the shim fakes (`freedreno`): the shim library's name.
    pub kernel: &'static str,
    /// The ICD manifest under the compilers folder's `icd/`.
    pub icd: &'static str,
    /// The Vulkan driver's name as halftrace's docs and tables use it (`turnip`).
    pub driver: &'static str,
    /// The compiler's own one-line summary per shader on stderr, where its statistics lack
    /// what the columns need (Mali's estimate, V3D's spills).
    pub summary_env: &'static [(&'static str, &'static str)],
}

impl Shim {
    /// The shim's library name under `lib/` of the compilers folder.
    pub fn library(&self) -> String {
        format!("lib{}_noop_drm_shim.so", self.kernel)
    }
}

/// A GPU model a shim fakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Model {
    /// The name `--family` takes (`a740`, `g610`, `lnl`, `ga102`, `v3d-71`).
    pub name: &'static str,
    /// What the tables call it.
    pub display: &'static str,
    /// Its architecture or generation.
    pub generation: &'static str,
    /// The shim's environment for this model.
    pub env: &'static [(&'static str, &'static str)],
}

/// Shorthand for the model lists.
pub const fn model(
    name: &'static str,
    display: &'static str,
    generation: &'static str,
    env: &'static [(&'static str, &'static str)],
) -> Model {
    Model { name, display, generation, env }
}

/// Whose names a driver's statistics use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stats {
    /// RADV's (ACO's): VGPRs, SGPRs, scratch per wave, waves per SIMD — the AMD tables.
    Aco,
    /// The driver's own: shown through the vendor-neutral columns.
    Own,
}

/// A disassembly halftrace counts the instruction mix of (`isa::counts`, `isa::mix`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Disassembly {
    /// AMD's (ACO's listing).
    Aco,
    /// Adreno's ir3.
    Ir3,
    /// NVIDIA's, as NAK prints it.
    Nak,
    /// Intel's (anv's "GEN assembly").
    Intel,
    /// Mali's Valhall and Bifrost.
    Mali,
}

/// A vendor's occupancy unit, in a table's column (`waves/core`) and in words.
#[derive(Clone, Copy, Debug)]
pub struct Occupancy {
    pub unit: &'static str,
    /// The unit in words (`waves per core`).
    pub words: &'static str,
    /// Whose unit and what to know of it (`Adreno`).
    pub note: &'static str,
}

/// Device quirks: what differs from the GPU default in how kernels are built for a vendor's
/// devices, each measured (`gpu::DeviceInfo` says why each exists).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Quirks {
    /// The largest private array the compiler keeps in registers, bytes (0: none known).
    pub register_array_bytes: u32,
    /// Whether the next child's entry goes to shared memory rather than registers.
    pub pending_shared: bool,
}

/// The GPU default: no known register-array limit, the pending entry in shared memory.
pub const GPU_DEFAULT: Quirks = Quirks { register_array_bytes: 0, pending_shared: true };

/// The vendor-neutral columns in table order, each as its heading.
pub const COLUMNS: [&str; 6] = [
    "registers per thread (32-bit)",
    "private memory per thread, bytes",
    "spill and fill instructions",
    "occupancy",
    "instructions",
    "the compiler's cycle estimate",
];

/// What a vendor's [`Vendor::neutral`] reads: the driver's statistics by its names, and what
/// halftrace counted or knows of the build.
pub struct Input<'a> {
    pub stats: &'a BTreeMap<String, f64>,
    /// The model's or family's generation (`Turing`, `RDNA3`), empty when unknown.
    pub generation: &'a str,
    /// The subgroup (wave) size the driver compiled for.
    pub subgroup_size: u32,
    /// Private loads and stores counted in the disassembly, where it names them.
    pub private_ops: Option<(u64, u64)>,
}

impl Input<'_> {
    /// The statistic named exactly `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.stats.get(name).copied()
    }
    /// The statistic named `name` in any case (RADV's names, as the row's own columns read
    /// them).
    pub fn get_any_case(&self, name: &str) -> Option<f64> {
        self.stats.iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| *v)
    }
    /// The sum of two statistics, where both are there.
    pub fn sum(&self, a: &str, b: &str) -> Option<f64> {
        self.get(a).zip(self.get(b)).map(|(a, b)| a + b)
    }
    /// The disassembly's private loads and stores together.
    pub fn private_ops(&self) -> Option<f64> {
        self.private_ops.map(|(l, s)| (l + s) as f64)
    }
}

/// The vendor-neutral columns of one kernel (occupancy in the vendor's unit).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Neutral {
    pub registers: Option<f64>,
    pub private_bytes: Option<f64>,
    pub spills: Option<f64>,
    pub occupancy: Option<f64>,
    pub instructions: Option<f64>,
    pub cycles: Option<f64>,
}

impl Vendor {
    /// The vendor of the Vulkan driver `id`.
    pub fn of_driver_id(id: vk::DriverId) -> Option<&'static Vendor> {
        REGISTRY.iter().copied().find(|v| v.driver_ids.contains(&id))
    }
    /// The vendor of a driver named `driver` ("radv Mesa 25.0.7", "turnip Mesa driver …").
    pub fn of_driver(driver: &str) -> Option<&'static Vendor> {
        let d = driver.to_lowercase();
        REGISTRY.iter().copied().find(|v| v.driver_names.iter().any(|n| d.contains(n)))
    }
    /// The vendor called `name`.
    pub fn named(name: &str) -> Option<&'static Vendor> {
        REGISTRY.iter().copied().find(|v| v.name == name)
    }
    /// Its place in table order.
    pub fn position(&self) -> usize {
        REGISTRY.iter().position(|v| v.name == self.name).unwrap_or(REGISTRY.len())
    }
    /// The vendor whose shim fakes kernel driver `kernel` for the Vulkan driver `id`.
    pub fn shimmed(kernel: &str, id: vk::DriverId) -> Option<&'static Vendor> {
        REGISTRY.iter().copied().find(|v| v.shim.is_some_and(|s| s.kernel == kernel) && v.driver_ids.contains(&id))
    }
}

impl std::fmt::Debug for Vendor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// Every model a shim fakes, with its vendor, in table order.
pub fn models() -> impl Iterator<Item = (&'static Vendor, &'static Model)> {
    REGISTRY.iter().flat_map(|v| v.models.iter().map(move |m| (*v, m)))
}

/// The model called `name` (case-insensitive) and its vendor.
pub fn find_model(name: &str) -> Option<(&'static Vendor, &'static Model)> {
    models().find(|(_, m)| m.name.eq_ignore_ascii_case(name))
}

/// A row's vendor: one of [`REGISTRY`], or none (a CPU implementation, an unknown driver).
/// Written as its name (empty for none), so files keep the `vendor` column as it was.
#[derive(Clone, Copy, Default)]
pub struct VendorId(pub Option<&'static Vendor>);

impl VendorId {
    pub fn of_driver(driver: &str) -> VendorId {
        VendorId(Vendor::of_driver(driver))
    }
    pub fn name(&self) -> &'static str {
        self.0.map_or("", |v| v.name)
    }
    pub fn get(&self) -> Option<&'static Vendor> {
        self.0
    }
    /// Whether the vendor's statistics are `s`'s names.
    pub fn stats_are(&self, s: Stats) -> bool {
        self.0.is_some_and(|v| v.stats == s)
    }
}

impl PartialEq for VendorId {
    fn eq(&self, o: &VendorId) -> bool {
        self.name() == o.name()
    }
}

impl PartialEq<&str> for VendorId {
    fn eq(&self, o: &&str) -> bool {
        self.name() == *o
    }
}

impl std::fmt::Debug for VendorId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::fmt::Display for VendorId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl serde::Serialize for VendorId {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for VendorId {
    /// A name no vendor has reads as none: the row's driver names it again where it is read.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<VendorId, D::Error> {
        let s = String::deserialize(d)?;
        Ok(VendorId(Vendor::named(&s)))
    }
}

/// Every vendor's [`Vendor::sources`] as a Markdown table (docs/vendors.md holds it for the
/// vendors GPUs have; a test keeps them equal).
pub fn column_table(vendors: &[&Vendor]) -> String {
    let names: Vec<&str> = vendors.iter().map(|v| v.name).collect();
    let mut md = format!("| column | {} |\n|---|{}\n", names.join(" | "), "---|".repeat(names.len()));
    for (i, col) in COLUMNS.iter().enumerate() {
        let cells: Vec<&str> = vendors.iter().map(|v| v.sources[i]).collect();
        md += &format!("| {col} | {} |\n", cells.join(" | "));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn real() -> Vec<&'static Vendor> {
        REGISTRY.iter().copied().filter(|v| !std::ptr::eq(*v, &fake::FAKE)).collect()
    }

    #[test]
    fn docs_hold_the_column_table() {
        let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/vendors.md")).unwrap();
        let want = column_table(&real());
        assert!(doc.contains(&want), "docs/vendors.md must hold the column table as the code has it:\n{want}");
    }

    #[test]
    fn each_driver_and_model_has_one_vendor() {
        assert_eq!(Vendor::of_driver("turnip Mesa driver Mesa 25.0.7").map(|v| v.name), Some("Qualcomm"));
        assert_eq!(Vendor::of_driver("radv Mesa 25.0.7").map(|v| v.name), Some("AMD"));
        assert_eq!(Vendor::of_driver("NVK Mesa 25.0.7").map(|v| v.name), Some("NVIDIA"));
        assert!(Vendor::of_driver("llvmpipe Mesa 25.0.7 (LLVM 19.1.7)").is_none());
        for (i, a) in REGISTRY.iter().enumerate() {
            for b in &REGISTRY[i + 1..] {
                assert_ne!(a.name, b.name);
                assert!(a.driver_ids.iter().all(|id| !b.driver_ids.contains(id)), "{} and {}", a.name, b.name);
            }
        }
        let all: Vec<_> = models().collect();
        for (i, (_, a)) in all.iter().enumerate() {
            assert!(all[i + 1..].iter().all(|(_, b)| b.name != a.name), "{} twice", a.name);
        }
        assert_eq!(find_model("A740").map(|(v, m)| (v.name, m.display)), Some(("Qualcomm", "Adreno 740")));
    }

    #[test]
    fn a_vendor_id_reads_back_as_written() {
        let v = VendorId(Vendor::named("Intel"));
        let s = serde_json::to_string(&v).unwrap();
        assert_eq!(s, "\"Intel\"");
        assert_eq!(serde_json::from_str::<VendorId>(&s).unwrap(), v);
        assert_eq!(serde_json::from_str::<VendorId>("\"Nobody\"").unwrap().name(), "");
    }
}
