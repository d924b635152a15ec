//! `halftrace isa`: the compiler's view. Builds each kernel of a matrix on each chosen device
//! — RADV null devices by family (AMD's production compiler, no GPU needed) or any device whose
//! driver exposes `VK_KHR_pipeline_executable_properties` — and reads what the driver says of
//! it: its statistics (registers, spills, scratch, LDS, code size, instruction mix, waves per
//! SIMD) and its disassembly ([`counts`]: packed and scalar fp16, fp32, scratch traffic). One
//! [`IsaRow`] per kernel × device; nothing is dispatched.

pub mod counts;
pub mod mix;
pub mod vendors;

use crate::base::Status;
use crate::bvh::BRANCHINGS;
use crate::gpu::executable::executables;
use crate::gpu::null::{self, Family};
use crate::gpu::{self, ContextOptions, Gpu, GpuError, Kernel, Source};
use crate::layout::LayoutId;
use crate::precision::{FcChoice, FloatControls};
use crate::report::isa::IsaRow;
use crate::variant::{KernelId, PacketImpl, Variant, PACKETS};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Which kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Matrix {
    /// Every layout and math at B = 4, P = 1.
    Quick,
    /// The default sweep's matrix ([`Variant::matrix`]), each P in the device's implementation.
    Default,
    /// Every layout, math, B and P; every packet implementation of each P > 1; float controls
    /// on, and off where the layout has such a build.
    Full,
}

/// One kernel to build: the variant (float controls resolved per device when `fc` is auto)
/// and the packet implementation (`None`: the device's choice).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Build {
    pub variant: Variant,
    pub fc: FcChoice,
    pub imp: Option<PacketImpl>,
}

/// The kernels of `m` for `layouts` (empty: every layout).
pub fn plan(m: Matrix, layouts: &[LayoutId]) -> Vec<Build> {
    let keep = |l: LayoutId| layouts.is_empty() || layouts.contains(&l) || l == LayoutId::f32();
    let auto = |v: Variant| Build { variant: v, fc: FcChoice::Auto, imp: None };
    let mut out = Vec::new();
    match m {
        Matrix::Quick => {
            for l in LayoutId::all().filter(|&l| keep(l)) {
                for &math in l.info().maths {
                    out.push(auto(Variant::new(l, 4, 1).with_math(math)));
                }
            }
        }
        Matrix::Default => out.extend(Variant::matrix().into_iter().filter(|v| keep(v.layout)).map(auto)),
        Matrix::Full => {
            for l in LayoutId::all().filter(|&l| keep(l)) {
                let fcs: &[FcChoice] =
                    if l.info().float_controls_off { &[FcChoice::On, FcChoice::Off] } else { &[FcChoice::On] };
                for &math in l.info().maths {
                    for b in BRANCHINGS {
                        for p in PACKETS {
                            let imps: &[Option<PacketImpl>] = if p == 1 {
                                &[Some(PacketImpl::Single)]
                            } else {
                                &[Some(PacketImpl::Subgroup), Some(PacketImpl::Shared), Some(PacketImpl::Hybrid)]
                            };
                            for &fc in fcs {
                                for &imp in imps {
                                    out.push(Build { variant: Variant::new(l, b, p).with_math(math), fc, imp });
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// Where kernels are built.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    /// RADV's null device of a family.
    Family(String),
    /// Another vendor's model under its drm-shim, built in a child process ([`vendors`]).
    Model(String),
    /// A device by index or name (its driver must expose pipeline statistics).
    Device(String),
}

/// What `isa` does.
#[derive(Clone, Debug)]
pub struct Config {
    pub targets: Vec<Target>,
    /// The matrix and layouts the builds come from (a model's child process plans the same).
    pub matrix: Matrix,
    pub layouts: Vec<LayoutId>,
    pub builds: Vec<Build>,
    /// Write every kernel's internal representations (NIR, the compiler's IR, disassembly)
    /// under `disasm/<device>/` of the output folder.
    pub disasm: Option<PathBuf>,
    pub validation: bool,
}

/// What a run produced.
pub struct Summary {
    pub rows: Vec<IsaRow>,
    /// Validation-layer messages, per device label.
    pub validation_messages: Vec<String>,
    /// What went wrong with a model's process (a driver that crashed), by model.
    pub notes: Vec<String>,
}

impl Matrix {
    /// The name `isa-model --matrix` takes.
    pub fn name(self) -> &'static str {
        match self {
            Matrix::Quick => "quick",
            Matrix::Default => "default",
            Matrix::Full => "full",
        }
    }
    pub fn parse(s: &str) -> Option<Matrix> {
        [Matrix::Quick, Matrix::Default, Matrix::Full].into_iter().find(|m| m.name() == s)
    }
}

/// Opens a target for statistics.
fn open(t: &Target, validation: bool) -> Result<(Gpu, Option<Family>), GpuError> {
    match t {
        Target::Family(f) => Ok((null::open(f, validation)?, null::family(f))),
        Target::Model(m) => Err(GpuError::Other(format!("model {m} opens in its own process (isa-model)"))),
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

/// Builds every kernel of `cfg` on every target; `each` sees each row as it is made. Models
/// are built in a child process each (`exe isa-model`).
pub fn run(cfg: &Config, exe: &Path, mut each: impl FnMut(&IsaRow)) -> anyhow::Result<Summary> {
    let mut rows = Vec::new();
    let mut messages = Vec::new();
    let mut notes = Vec::new();
    for t in &cfg.targets {
        if let Target::Model(name) = t {
            let m = vendors::model(name).ok_or_else(|| anyhow::anyhow!("--family {name}: no such model"))?;
            let dir = vendors::compilers().map_err(anyhow::Error::msg)?;
            let mut args = vec!["--matrix".to_string(), cfg.matrix.name().to_string()];
            if !cfg.layouts.is_empty() {
                args.push("--layouts".into());
                args.push(cfg.layouts.iter().map(|l| l.name()).collect::<Vec<_>>().join(","));
            }
            if cfg.validation {
                args.push("--validation".into());
            }
            if let Some(d) = &cfg.disasm {
                args.push("--disasm".into());
                args.push(d.join(m.name).display().to_string());
            }
            let run = vendors::run_model(exe, &m, &dir, &args, &cfg.builds)?;
            for r in &run.rows {
                each(r);
            }
            notes.extend(run.note);
            rows.extend(run.rows);
            continue;
        }
        let (g, fam) = open(t, cfg.validation)?;
        let label = match t {
            Target::Family(f) => f.clone(),
            _ => slug(&g.info.name),
        };
        let who = Who { family: fam, model: None };
        for b in &cfg.builds {
            let row = build_one(&g, &who, b, cfg.disasm.as_deref().map(|d| d.join(&label)).as_deref(), |_| {})?;
            each(&row);
            rows.push(row);
        }
        messages.extend(g.validation_messages().into_iter().map(|m| format!("{}: {m}", g.info.name)));
    }
    crate::report::isa::set_ratios(&mut rows);
    Ok(Summary { rows, validation_messages: messages, notes })
}

/// Builds `builds` on the device a drm-shim fakes as model `m` (this process was started with
/// its environment: `halftrace isa-model`), printing each row as one line of JSON as it is
/// made and, on stderr, [`vendors::MARKER`] and the kernel before building it.
pub fn run_model_here(
    m: &vendors::Model,
    builds: &[Build],
    validation: bool,
    disasm: Option<&Path>,
) -> anyhow::Result<Vec<String>> {
    use std::io::Write as _;
    let g = Gpu::new(&ContextOptions { validation, statistics: true, ..Default::default() })?;
    anyhow::ensure!(
        g.info.compile_only,
        "{}: {} is not under a drm-shim here (LD_PRELOAD={})",
        m.name,
        g.info.name,
        std::env::var("LD_PRELOAD").unwrap_or_default()
    );
    let who = Who { family: None, model: Some(*m) };
    let mut out = std::io::stdout().lock();
    for b in builds {
        let row = build_one(&g, &who, b, disasm, |k| eprintln!("{}{k}", vendors::MARKER))?;
        writeln!(out, "{}", serde_json::to_string(&row)?)?;
        out.flush()?;
    }
    Ok(g.validation_messages().into_iter().map(|msg| format!("{}: {msg}", m.name)).collect())
}

/// What a device is besides its driver's name: an AMD family, or a model under a drm-shim.
struct Who {
    family: Option<Family>,
    model: Option<vendors::Model>,
}

/// What a device's build of the kernels used, in words.
fn device_build(g: &Gpu) -> String {
    let b = g.info.build();
    format!(
        "{}, {}, SPIR-V 1.{}",
        if b.f64 { "fp64" } else { "no fp64 (integer edge fallback)" },
        if b.storage16 { "16-bit storage" } else { "fp16 nodes from 32-bit words" },
        b.spirv_minor
    )
}

/// One kernel on one device: its row, skipped when the device lacks what it needs, failed
/// when the driver refuses it.
fn build_one(
    g: &Gpu,
    who: &Who,
    b: &Build,
    disasm: Option<&Path>,
    before: impl FnOnce(&str),
) -> anyhow::Result<IsaRow> {
    let v = b.variant;
    let (family, generation, device) = match (who.model, who.family) {
        (Some(m), _) => (m.name.to_string(), m.generation.to_string(), format!("{} ({})", m.display, m.driver.name())),
        (None, Some(f)) => (f.name.to_string(), f.generation.to_string(), g.info.name.clone()),
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
    row.vendor = crate::report::isa::vendor_of(&row.driver).to_string();
    let imp = b.imp.unwrap_or_else(|| gpu::kernel::choose_impl(g, &v, None));
    row.packet_impl = format!("{imp:?}").to_lowercase();
    let resolved = match gpu::support::resolve(&g.info, v, b.fc) {
        Ok(r) => r,
        Err(why) => {
            // Named as asked: --full asks for both float-control modes of a layout.
            let asked = v.with_fc(if b.fc == FcChoice::Off { FloatControls::Off } else { FloatControls::On });
            row.kernel = KernelId::new(asked, imp, false).name();
            row.float_controls = asked.fc.name().into();
            row.status = Status::Skipped(why);
            return Ok(row);
        }
    };
    let k = KernelId::new(resolved, imp, false);
    row.kernel = k.name();
    row.float_controls = resolved.fc.name().into();
    before(&row.kernel);
    let t0 = Instant::now();
    let kernel = match Kernel::build(g, &k, &Source::Builtin) {
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
    if row.vendor == "AMD" {
        // GFX9 on has scratch_* instructions; an AMD device of unknown generation may not.
        let flat_scratch = matches!(who.family.map(|f| f.generation), Some(g) if !g.starts_with("GCN") || g == "GCN5");
        if let Some((_, asm)) = e.representations.iter().find(|(n, _)| n.to_lowercase().contains("assembly")) {
            row.asm = Some(counts::count(asm, flat_scratch));
        }
    } else if let Some((isa, text)) =
        e.representations.iter().find_map(|(n, t)| mix::Isa::of(&row.vendor, n).map(|i| (i, t)))
    {
        row.asm = Some(mix::count(isa, text));
    }
    row.fill_known();
    if let Some(dir) = disasm {
        std::fs::create_dir_all(dir)?;
        for (name, text) in &e.representations {
            crate::fsx::write_atomic(&dir.join(format!("{}.{}.txt", row.kernel, slug(name))), text.as_bytes())?;
        }
    }
    Ok(row)
}

/// The families of [`null::FAMILIES`] the installed RADV opens a null device for. RADV
/// aborts the process on a family it does not know, so each is tried in a child process:
/// `exe probe-family` (the halftrace binary) with `RADV_FORCE_FAMILY` set, a few tens of
/// milliseconds each, eight at a time.
pub fn known_families(exe: &Path) -> Vec<Family> {
    let probe = |f: &Family| -> bool {
        std::process::Command::new(exe)
            .arg("probe-family")
            .env("RADV_FORCE_FAMILY", f.name)
            .stdin(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .output()
            .is_ok_and(|o| {
                o.status.success() && String::from_utf8_lossy(&o.stdout).lines().any(|l| null::family_of(l) == Some(*f))
            })
    };
    let mut ok = vec![false; null::FAMILIES.len()];
    for (chunk, flags) in null::FAMILIES.chunks(8).zip(ok.chunks_mut(8)) {
        std::thread::scope(|s| {
            let hs: Vec<_> = chunk.iter().map(|f| s.spawn(move || probe(f))).collect();
            for (h, flag) in hs.into_iter().zip(flags.iter_mut()) {
                *flag = h.join().unwrap_or(false);
            }
        });
    }
    null::FAMILIES.iter().zip(ok).filter(|(_, k)| *k).map(|(f, _)| *f).collect()
}

/// The families `isa` builds for by default: those of [`null::DEFAULT_FAMILIES`] in `known`.
pub fn default_families(known: &[Family]) -> Vec<String> {
    null::DEFAULT_FAMILIES.iter().filter(|n| known.iter().any(|k| k.name == **n)).map(|n| n.to_string()).collect()
}
