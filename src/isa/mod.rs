//! `halftrace isa`: the compiler's view. Builds each kernel of a matrix on each chosen device
//! — RADV null devices by family (AMD's production compiler, no GPU needed) or any device whose
//! driver exposes `VK_KHR_pipeline_executable_properties` — and reads what the driver says of
//! it: its statistics (registers, spills, scratch, LDS, code size, instruction mix, waves per
//! SIMD) and its disassembly ([`counts`]: packed and scalar fp16, fp32, scratch traffic). One
//! [`IsaRow`] per kernel × device; nothing is dispatched.

pub mod aco;
pub mod counts;
pub mod mix;
pub mod shim;
mod targets;

pub use targets::{default_families, families, known_families, release_targets, releases_targets, Target};

use crate::base::Status;
use crate::gpu::executable::executables;
use crate::gpu::null::{self, Family};
use crate::gpu::{support, ContextOptions, Gpu, GpuError, Kernel};
use crate::layout::LayoutId;
use crate::precision::{FcChoice, FloatControls};
use crate::report::isa::IsaRow;
use crate::report::What;
pub use crate::variant::Matrix;
use crate::variant::{self, KernelId, KernelSpec};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The kernels of `m` for `layouts` (empty: every layout; f32, the reference, always): the
/// device's packet implementation, except [`Matrix::Full`], which builds every one.
pub fn plan(m: Matrix, layouts: &[LayoutId]) -> Vec<KernelSpec> {
    let keep = |l: LayoutId| layouts.is_empty() || layouts.contains(&l) || l == LayoutId::f32();
    let imps = if m == Matrix::Full { variant::every_impl } else { variant::device_impl };
    variant::matrix(m, &imps).into_iter().filter(|k| keep(k.variant.layout)).collect()
}

/// [`plan`]'s kernels at `branchings` only (empty: every B): what a model's child builds when
/// the run asks for some B (`memory --compilers`: the B it models).
pub fn plan_at(m: Matrix, layouts: &[LayoutId], branchings: &[usize]) -> Vec<KernelSpec> {
    let mut p = plan(m, layouts);
    p.retain(|k| branchings.is_empty() || branchings.contains(&k.variant.branching));
    p
}

/// `halftrace isa-model`'s arguments (a hidden command: the child process that builds the
/// matrix on one model): built here from the typed values, parsed back in a test.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct ModelArgs {
    /// A model under its drm-shim (this process has its environment) or an AMD family.
    #[arg(long)]
    pub model: String,
    /// layouts (isa --quick), cover, default, full or singles (`variant::Matrix`).
    #[arg(long, default_value = "default")]
    pub matrix: String,
    #[arg(long, value_delimiter = ',')]
    pub layouts: Vec<LayoutId>,
    /// Only these branching factors of the matrix (empty: every one).
    #[arg(long, value_delimiter = ',')]
    pub branchings: Vec<usize>,
    #[arg(long)]
    pub validation: bool,
    /// Write the representations under this folder.
    #[arg(long)]
    pub disasm: Option<PathBuf>,
    /// Build each kernel with its named branches marked ([`crate::variant::Source::Marked`]).
    #[arg(long)]
    pub marked: bool,
}

impl ModelArgs {
    /// The child's command line.
    pub fn argv(&self) -> crate::argv::Argv {
        crate::argv::Argv::new("isa-model")
            .opt("model", Some(&self.model))
            .opt("matrix", Some(&self.matrix))
            .list("layouts", &self.layouts)
            .list("branchings", &self.branchings)
            .flag("validation", self.validation)
            .opt("disasm", self.disasm.as_ref().map(|d| d.display()))
            .flag("marked", self.marked)
    }
}

/// What `isa` does.
#[derive(Clone, Debug)]
pub struct Config {
    pub targets: Vec<Target>,
    /// The matrix, layouts and branching factors (empty: every one) the builds come from
    /// ([`Config::builds`]; a model's child process plans the same).
    pub matrix: Matrix,
    pub layouts: Vec<LayoutId>,
    pub branchings: Vec<usize>,
    /// Write every kernel's internal representations (NIR, the compiler's IR, disassembly)
    /// under `disasm/<device>/` of the output folder.
    pub disasm: Option<PathBuf>,
    pub validation: bool,
    /// Whether the targets come from more than one compilers release: each child's
    /// representations then go under `disasm/<name>-mesa-<release>/`.
    pub releases: usize,
}

impl Config {
    /// The kernels built on each target ([`plan_at`]).
    pub fn builds(&self) -> Vec<KernelSpec> {
        plan_at(self.matrix, &self.layouts, &self.branchings)
    }
}

/// What a run produced.
pub struct Summary {
    pub rows: Vec<IsaRow>,
    /// Validation-layer messages, per device label.
    pub validation_messages: Vec<String>,
    /// What went wrong with a model's process (a driver that crashed), by model.
    pub notes: Vec<String>,
}

/// Opens a target for statistics.
fn open(t: &Target, validation: bool) -> Result<(Gpu, Option<Family>), GpuError> {
    match t {
        Target::Family(f, None) => Ok((null::open(f, validation)?, null::family(f))),
        Target::Family(f, Some(_)) | Target::Model(f, _) => {
            Err(GpuError::Other(format!("{f} opens under its drm-shim in its own process (isa-model)")))
        }
        Target::Device(d) => {
            let g = Gpu::new(&ContextOptions {
                device: Some(d.clone()),
                validation,
                statistics: true,
                ..Default::default()
            })?;
            let fam = null::family_of(&g.info.name);
            Ok((g, fam))
        }
    }
}

/// A file-name-safe spelling of a device label.
fn slug(s: &str) -> String {
    let t: String = s.chars().map(|c| if c.is_ascii_alphanumeric() { c.to_ascii_lowercase() } else { '-' }).collect();
    t.split('-').filter(|p| !p.is_empty()).collect::<Vec<_>>().join("-")
}

/// Builds every kernel of `cfg` on every target; `each` sees each row as it is made (a
/// model's rows when its process is done). Models are built in a child process each (`exe
/// isa-model`), as many at once as there are cores (each compiler runs on one).
pub fn run(cfg: &Config, exe: &Path, mut each: impl FnMut(&IsaRow)) -> anyhow::Result<Summary> {
    use rayon::prelude::*;
    let mut rows = Vec::new();
    let mut messages = Vec::new();
    let mut notes = Vec::new();
    let builds = cfg.builds();
    // Whatever opens under a drm-shim: a child process each, as many at once as there are cores.
    let children: Vec<&Target> = cfg.targets.iter().filter(|t| child_of(t).is_some()).collect();
    let mut runs: Vec<Option<shim::ModelRun>> =
        children.par_iter().map(|t| run_model(cfg, exe, t, &builds).map(Some)).collect::<anyhow::Result<_>>()?;
    let mut next_run = runs.iter_mut();
    for t in &cfg.targets {
        if child_of(t).is_some() {
            let run = next_run.next().and_then(Option::take).expect("one run per model");
            for r in &run.rows {
                each(r);
            }
            notes.extend(run.note);
            rows.extend(run.rows);
            continue;
        }
        let (g, fam) = open(t, cfg.validation)?;
        let label = match t {
            Target::Family(f, _) => f.clone(),
            _ => slug(&g.info.name),
        };
        let who = Who { family: fam, model: None };
        for b in &builds {
            let row = build_one(&g, &who, b, cfg.disasm.as_deref().map(|d| d.join(&label)).as_deref(), |_| {})?;
            each(&row);
            rows.push(row);
        }
        messages.extend(g.validation_messages().into_iter().map(|m| format!("{}: {m}", g.info.name)));
    }
    crate::report::isa::set_ratios(&mut rows);
    Ok(Summary { rows, validation_messages: messages, notes })
}

/// The name and compilers folder of a target built in a child process under its drm-shim: a
/// model, or an AMD family under the amdgpu shim.
fn child_of(t: &Target) -> Option<(&str, &Path)> {
    match t {
        Target::Model(name, dir) | Target::Family(name, Some(dir)) => Some((name, dir)),
        _ => None,
    }
}

/// The rows of a model or a shimmed AMD family, built in its own process.
fn run_model(cfg: &Config, exe: &Path, t: &Target, builds: &[KernelSpec]) -> anyhow::Result<shim::ModelRun> {
    let (name, dir) = child_of(t).expect("a child's target");
    let (v, m) = match t {
        Target::Family(..) => (
            &crate::vendor::amd::AMD,
            shim::family_model(name).ok_or_else(|| anyhow::anyhow!("--family {name}: no such AMD family"))?,
        ),
        _ => crate::vendor::find_model(name)
            .map(|(v, m)| (v, *m))
            .ok_or_else(|| anyhow::anyhow!("--family {name}: no such model"))?,
    };
    let sub = if cfg.releases > 1 { format!("{}-mesa-{}", m.name, shim::release(dir)) } else { m.name.to_string() };
    let args = ModelArgs {
        model: m.name.into(),
        matrix: cfg.matrix.name().into(),
        layouts: cfg.layouts.clone(),
        branchings: cfg.branchings.clone(),
        validation: cfg.validation,
        disasm: cfg.disasm.as_ref().map(|d| d.join(sub)),
        marked: false,
    };
    shim::run_model(exe, (v, &m), dir, &args.argv(), builds)
}

/// Builds `builds` in this process (`halftrace isa-model`) on model `name` — a device a
/// drm-shim fakes (this process was started with its environment) or an AMD family's RADV
/// null device — printing each row as one line of JSON as it is made and, on stderr,
/// [`shim::MARKER`] and the kernel before building it.
pub fn run_model_here(
    name: &str,
    builds: &[KernelSpec],
    validation: bool,
    disasm: Option<&Path>,
) -> anyhow::Result<Vec<String>> {
    use std::io::Write as _;
    let (g, who) = match crate::vendor::find_model(name) {
        Some((v, m)) => {
            let g = Gpu::new(&ContextOptions { validation, statistics: true, ..Default::default() })?;
            anyhow::ensure!(
                g.info.compile_only,
                "{}: {} is not under a drm-shim here (LD_PRELOAD={})",
                m.name,
                g.info.name,
                std::env::var("LD_PRELOAD").unwrap_or_default()
            );
            (g, Who { family: None, model: Some((v, *m)) })
        }
        None => (null::open(name, validation)?, Who { family: null::family(name), model: None }),
    };
    let mut out = std::io::stdout().lock();
    for b in builds {
        let row = build_one(&g, &who, b, disasm, |k| eprintln!("{}{k}", shim::MARKER))?;
        writeln!(out, "{}", serde_json::to_string(&row)?)?;
        out.flush()?;
    }
    Ok(g.validation_messages().into_iter().map(|msg| format!("{name}: {msg}")).collect())
}

/// Builds `builds` on AMD family `family` in a child process (`exe isa-model`; under the amdgpu
/// shim of the compilers folder `amd` where given: [`shim::amd_shim`]) with ACO's
/// printouts on (`ACO_DEBUG=perfinfo`, `RADV_DEBUG=preoptir`, Mesa's shader cache off so
/// that every kernel is compiled and printed): each kernel's row beside its program as ACO
/// estimated it ([`aco::Program`]), or why that printout could not be read.
pub fn aco_programs(
    exe: &Path,
    family: &str,
    matrix: Matrix,
    layouts: &[LayoutId],
    amd: Option<&Path>,
    marked: bool,
) -> anyhow::Result<Vec<(IsaRow, Result<aco::Program, String>)>> {
    let args = ModelArgs {
        model: family.into(),
        matrix: matrix.name().into(),
        layouts: layouts.to_vec(),
        branchings: Vec::new(),
        validation: false,
        disasm: None,
        marked,
    };
    // Under the amdgpu shim of a compilers folder (Mesa 26 on), by the folder's copy of this binary.
    let (exe, env) = match amd.and_then(|d| Some((d, shim::amd_shim(d)?))) {
        Some((d, s)) => (shim::child_exe(exe, d)?, shim::family_environment(&s, family, d)),
        None => (exe.to_path_buf(), Vec::new()),
    };
    let (stdout, status, stderr) = shim::run_child(
        std::process::Command::new(&exe)
            .args(&args.argv().0)
            .envs(env)
            .env("ACO_DEBUG", "perfinfo")
            .env("RADV_DEBUG", "preoptir")
            .env("MESA_SHADER_CACHE_DISABLE", "true"),
    )?;
    if !status.success() {
        let tail: Vec<&str> = stderr.lines().filter(|l| !l.starts_with('\t')).rev().take(3).collect();
        anyhow::bail!("--family {family}: the compiler's process failed ({status}): {}", tail.join(" | "));
    }
    let rows: Vec<IsaRow> =
        stdout.lines().map(|l| serde_json::from_str(l).map(IsaRow::typed)).collect::<Result<_, _>>()?;
    // Each kernel's printout runs from its marker to the next one.
    let mut sections: BTreeMap<String, &str> = BTreeMap::new();
    let mut parts = stderr.split(shim::MARKER).skip(1);
    for part in parts.by_ref() {
        let (kernel, text) = part.split_once('\n').unwrap_or((part, ""));
        sections.insert(kernel.trim().to_string(), text);
    }
    Ok(rows
        .into_iter()
        .map(|r| {
            let p = if !r.status.is_ok() {
                Err(format!("not built: {}", r.status))
            } else {
                match sections.get(&r.kernel) {
                    Some(text) => aco::Program::from_printout(text).map_err(|e| format!("{}: {e}", r.kernel)),
                    None => Err(format!("{}: no printout after its marker", r.kernel)),
                }
            };
            (r, p)
        })
        .collect())
}

/// What a device is besides its driver's name: an AMD family, or a model under a drm-shim.
struct Who {
    family: Option<Family>,
    model: Option<(&'static crate::vendor::Vendor, crate::vendor::Model)>,
}

/// What a device's build of the kernels used, in words.
fn device_build(g: &Gpu) -> String {
    let b = g.info.build();
    format!(
        "{}, SPIR-V 1.{}{}{}",
        if b.storage16 { "16-bit storage" } else { "fp16 nodes from 32-bit words" },
        b.spirv_minor,
        if b.register_array_bytes > 0 {
            format!(", stacks allocated past {} B (smaller private arrays stay in registers)", b.register_array_bytes)
        } else {
            String::new()
        },
        if b.pending_shared { "" } else { ", the next child's entry held in registers" }
    )
}

/// One kernel on one device: its row, skipped when the device lacks what it needs, failed
/// when the driver refuses it.
fn build_one(
    g: &Gpu,
    who: &Who,
    b: &KernelSpec,
    disasm: Option<&Path>,
    before: impl FnOnce(&str),
) -> anyhow::Result<IsaRow> {
    let v = b.variant;
    let (family, generation, device) = match (who.model, who.family) {
        (Some((v, m)), _) => (
            m.name.to_string(),
            m.generation.to_string(),
            format!("{} ({})", m.display, v.shim.map_or(v.name, |s| s.driver)),
        ),
        // Under the amdgpu shim the device has a real GPU's name: said, so that its label is the
        // family's as a null device's is.
        (None, Some(f)) => (
            f.name.to_string(),
            f.generation.to_string(),
            match crate::gpu::device::shim().filter(|_| g.info.compile_only) {
                Some(kernel) => format!("{} ({kernel} shim)", g.info.name),
                None => g.info.name.clone(),
            },
        ),
        (None, None) => (String::new(), String::new(), g.info.name.clone()),
    };
    let mut row = IsaRow {
        device,
        family,
        generation,
        driver: g.info.driver.clone(),
        device_build: device_build(g),
        version: env!("CARGO_PKG_VERSION").into(),
        commit: env!("HALFTRACE_COMMIT").into(),
        layout: v.layout.name().into(),
        math: v.math.name().into(),
        branching: v.branching,
        packet: v.packet,
        ..IsaRow::default()
    };
    row.vendor = crate::vendor::VendorId::of_driver(&row.driver);
    let imp = support::packet_impl(&g.info, b);
    row.packet_impl = format!("{imp:?}").to_lowercase();
    let d = match support::decide(&g.info, b) {
        Ok(d) => d,
        Err(why) => {
            // Named as asked: --full asks for both float-control modes of a layout.
            let asked = v.with_fc(if b.fc == FcChoice::Off { FloatControls::Off } else { FloatControls::On });
            let id = KernelId::new(asked, imp, false);
            (row.kernel, row.what) = (id.name(), What::Builtin(id));
            row.float_controls = asked.fc.name().into();
            row.status = Status::Skipped(why);
            return Ok(row);
        }
    };
    let k = d.id;
    (row.kernel, row.what) = (k.name(), What::Builtin(k.with_stats(false)));
    row.float_controls = k.variant.fc.name().into();
    before(&row.kernel);
    let t0 = Instant::now();
    let kernel = match Kernel::build(g, &d, &b.source) {
        Ok(k) => k,
        Err(GpuError::Unsupported(why)) => {
            row.status = Status::Skipped(why);
            return Ok(row);
        }
        Err(e) => {
            row.status = Status::Failed(format!("did not build: {e}"));
            return Ok(row);
        }
    };
    row.build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let exes = match executables(g, &kernel.pipe) {
        Ok(e) => e,
        Err(e) => {
            row.status = Status::Failed(format!("built, but its statistics could not be read: {e}"));
            return Ok(row);
        }
    };
    let Some(e) = exes.first() else {
        row.status = Status::Failed("the driver reports no executable for the pipeline".into());
        return Ok(row);
    };
    row.subgroup_size = e.subgroup_size;
    row.stats = e.statistics.iter().map(|s| (s.name.clone(), s.value)).collect();
    // The vendor's disassembly, where its driver prints one.
    let listing = e.representations.iter().find(|(n, _)| n.to_lowercase().contains("assembly"));
    row.asm = match (row.vendor.get().and_then(|v| v.disassembly), listing) {
        (Some(mix::Isa::Aco), Some((_, asm))) => {
            // GFX9 on has scratch_* instructions; an AMD device of unknown generation may not.
            let flat_scratch =
                matches!(who.family.map(|f| f.generation), Some(g) if !g.starts_with("GCN") || g == "GCN5");
            Some(counts::count(asm, flat_scratch))
        }
        (Some(isa), Some((_, text))) => Some(mix::count(isa, text)),
        _ => None,
    };
    row.fill_known();
    if let Some(dir) = disasm {
        std::fs::create_dir_all(dir)?;
        for (name, text) in &e.representations {
            crate::fsx::write_atomic(&dir.join(format!("{}.{}.txt", row.kernel, slug(name))), text.as_bytes())?;
        }
    }
    Ok(row)
}
