//! A sweep's configuration: `--config sweep.toml` (every key in `sweep.example.toml`) with
//! flags over it, checked when read.

use super::Shard;
use crate::baseline::BaselineId;
use crate::bvh;
use crate::layout::LayoutId;
use crate::precision::{FcChoice, Math};
use crate::rays::{RayKind, RayParams};
use crate::runner::Plan;
use crate::variant::{Variant, LAYOUT_BRANCHINGS, PACKETS, SERIES_LAYOUTS};
use anyhow::Context;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// A sweep, as given by `--config sweep.toml` or by flags (see `sweep.example.toml`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// OBJ / .obj.gz files.
    pub scenes: Vec<PathBuf>,
    /// primary, ao, diffuse, grazing or FILE.npy.
    pub rays: Vec<String>,
    /// Layouts and baselines from the registry (baselines are skipped, with one line in the
    /// report, on devices without what they need).
    pub layouts: Vec<String>,
    /// The layouts that get the B and P series; every other one runs at `layout_branchings`.
    pub series: Vec<String>,
    /// Branching factors swept at P = 1 (for the `series` layouts).
    pub branchings: Vec<usize>,
    /// Branching factors at which every layout runs with P = 1 (the layouts comparison; also
    /// read as `scheme_branchings`, its former name).
    #[serde(alias = "scheme_branchings")]
    pub layout_branchings: Vec<usize>,
    /// Packet sizes swept at B = `packet_branching`.
    pub packets: Vec<usize>,
    /// Math modes of the layouts that have several: f16, f32, mixed.
    pub maths: Vec<String>,
    pub packet_branching: usize,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    pub warmup: usize,
    pub repeat: usize,
    /// Vulkan device index or name substring ("" = default device).
    pub device: String,
    /// Seconds one dispatch may run before its kernel is declared hung.
    pub kernel_timeout: f64,
    /// Float-control modes of the kernels: auto (on where the device has them, else off where
    /// the layout has such a build), on, or off.
    pub float_controls: FcChoice,
    /// User kernels (`[[kernel]]` tables), each run as its own rows.
    pub kernel: Vec<KernelTable>,
    /// Run only this share of the job list (`--shard K/N` or a Slurm array task; not a file
    /// key: the same config serves every shard).
    #[serde(skip)]
    pub shard: Option<Shard>,
    /// Wall-time budget in seconds (`--budget`; not a file key): no job starts once the time
    /// run so far plus the longest job so far would exceed it (the first job always runs);
    /// `--resume` runs the rest.
    #[serde(skip)]
    pub budget: Option<f64>,
}

/// A user kernel in a sweep: a GLSL compute file or SPIR-V module standing in for the built-in
/// kernel of one variant, validated against that layout's CPU reference before it is timed.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct KernelTable {
    /// The `kernel` column of its rows.
    pub name: String,
    pub layout: String,
    /// `.comp`/`.glsl` (compiled with the variant's defines and includes) or `.spv`.
    pub file: PathBuf,
    /// Default 4.
    pub branching: Option<usize>,
    /// Default 1.
    pub packet: Option<usize>,
    /// Default: the layout's default math.
    pub math: Option<String>,
    /// Default: the sweep's ray kinds.
    pub rays: Option<Vec<String>>,
    /// Seconds one dispatch of this kernel may run before it is declared hung. Default: the
    /// sweep's `kernel_timeout` (a kernel under development can have a short one without the
    /// built-in kernels beside it being judged by it).
    pub kernel_timeout: Option<f64>,
}

impl KernelTable {
    /// The variant whose built-in kernel this one stands in for.
    pub fn variant(&self) -> anyhow::Result<Variant> {
        let what = || format!("[[kernel]] '{}'", self.name);
        anyhow::ensure!(
            BaselineId::parse(&self.layout).is_none(),
            "{}: layout {} is a baseline; a kernel needs a BVH layout",
            what(),
            self.layout
        );
        let layout: LayoutId = self.layout.parse().with_context(what)?;
        let math = match &self.math {
            Some(m) => Some(m.parse::<Math>().map_err(anyhow::Error::msg).with_context(what)?),
            None => None,
        };
        Variant::checked(layout, self.branching.unwrap_or(4), self.packet.unwrap_or(1), math)
            .map_err(|e| anyhow::anyhow!("{}: {} {e}", what(), e.parameter()))
    }
}

/// The bundled scene of the default sweep.
pub const DEFAULT_SCENE: &str = "scenes/teapot.obj";

impl Default for Config {
    fn default() -> Config {
        Config {
            scenes: vec![PathBuf::from(DEFAULT_SCENE)],
            rays: vec!["primary".into(), "ao".into()],
            layouts: LayoutId::all()
                .map(|l| l.name())
                .chain(BaselineId::all().map(|b| b.name()))
                .map(String::from)
                .collect(),
            series: SERIES_LAYOUTS.iter().map(|s| s.to_string()).collect(),
            branchings: bvh::BRANCHINGS.to_vec(),
            layout_branchings: LAYOUT_BRANCHINGS.to_vec(),
            packets: PACKETS.to_vec(),
            maths: vec!["f16".into(), "f32".into()],
            packet_branching: 4,
            width: 256,
            height: 256,
            seed: 1,
            warmup: 2,
            repeat: 10,
            device: String::new(),
            kernel_timeout: crate::gpu::DEFAULT_KERNEL_TIMEOUT_S,
            float_controls: FcChoice::Auto,
            kernel: Vec::new(),
            shard: None,
            budget: None,
        }
    }
}

/// Refuses a scene list (named `what` in the message) with a file named twice, two files of one
/// short name, or a name that cannot stand in a report ([`crate::scene::checked_name`]): rows
/// name their scene by its short name, and two of one name would write rows that `--resume`
/// and `report` cannot tell apart.
pub fn check_scenes(what: &str, scenes: &[PathBuf]) -> anyhow::Result<()> {
    for (i, a) in scenes.iter().enumerate() {
        crate::scene::checked_name(a).with_context(|| what.to_string())?;
        for b in &scenes[..i] {
            anyhow::ensure!(
                !crate::fsx::same_file(a, b),
                "{what}: {} and {} are the same file",
                b.display(),
                a.display()
            );
            let (na, nb) = (crate::scene::scene_name(a), crate::scene::scene_name(b));
            anyhow::ensure!(
                na != nb,
                "{what}: {} and {} would both be '{na}' in the results; rename one",
                b.display(),
                a.display()
            );
        }
    }
    Ok(())
}

impl Config {
    pub fn load(path: &Path) -> anyhow::Result<Config> {
        let bytes = crate::fsx::read_regular(path).with_context(|| format!("reading {}", path.display()))?;
        let text = String::from_utf8(bytes).with_context(|| format!("reading {}: not UTF-8 text", path.display()))?;
        let c: Config = toml::from_str(&text).with_context(|| format!("{}: invalid sweep config", path.display()))?;
        c.check().with_context(|| path.display().to_string())?;
        Ok(c)
    }

    /// Checks every value names something that exists, and returns them parsed: the sweep as
    /// typed values, read once here (nothing after it parses a string of the configuration).
    pub fn check(&self) -> anyhow::Result<Sweep> {
        anyhow::ensure!(!self.scenes.is_empty(), "scenes: at least one scene is needed");
        anyhow::ensure!(!self.rays.is_empty(), "rays: at least one ray kind is needed");
        anyhow::ensure!(!self.layouts.is_empty(), "layouts: at least one layout or baseline is needed");
        check_scenes("scenes", &self.scenes)?;
        let mut kinds = Kinds::default();
        let mut rays = Vec::new();
        for r in &self.rays {
            rays.push(kinds.spelled(r.parse::<RayKind>()?));
        }
        let (mut layouts, mut baselines) = (Vec::new(), Vec::new());
        for l in &self.layouts {
            match BaselineId::parse(l) {
                Some(b) => baselines.push(b),
                None => layouts.push(l.parse::<LayoutId>().context("layouts")?),
            }
        }
        let mut series = Vec::new();
        for l in &self.series {
            series.push(l.parse::<LayoutId>().context("series")?);
        }
        for &b in self.branchings.iter().chain(&self.layout_branchings).chain([&self.packet_branching]) {
            bvh::check_branching(b).context("branchings")?;
        }
        for &p in &self.packets {
            anyhow::ensure!(PACKETS.contains(&p), "packets: {p} is not one of 1, 4, 8, 16, 32, 64");
        }
        let mut maths = Vec::new();
        for m in &self.maths {
            maths.push(m.parse::<Math>().map_err(anyhow::Error::msg).context("maths")?);
        }
        anyhow::ensure!(self.repeat >= 1, "repeat must be at least 1");
        crate::units::check_seconds("kernel_timeout", self.kernel_timeout).map_err(anyhow::Error::msg)?;
        anyhow::ensure!(self.width > 0 && self.height > 0, "width and height must be positive");
        crate::rays::check_image_size(self.width, self.height).map_err(anyhow::Error::msg)?;
        let mut kernels = Vec::new();
        for (i, k) in self.kernel.iter().enumerate() {
            anyhow::ensure!(
                !k.name.trim().is_empty() && !k.name.chars().any(char::is_control) && !k.name.contains('|'),
                "[[kernel]] name {:?}: name it with printable characters (no control characters or '|'; it is a \
                 report column)",
                k.name
            );
            anyhow::ensure!(
                !k.name.starts_with("trav_") && BaselineId::all().all(|b| b.imp().kernel() != k.name),
                "[[kernel]] '{}': trav_… and the baselines' kernel names are the built-in kernels'; name it otherwise",
                k.name
            );
            let variant = k.variant()?;
            let rays = match &k.rays {
                Some(names) => {
                    let mut rays = Vec::new();
                    for r in names {
                        rays.push(kinds.spelled(r.parse().with_context(|| format!("[[kernel]] '{}'", k.name))?));
                    }
                    Some(rays)
                }
                None => None,
            };
            anyhow::ensure!(k.file.is_file(), "[[kernel]] '{}': {} is not a readable file", k.name, k.file.display());
            anyhow::ensure!(
                !self.kernel[..i].iter().any(|o| o.name == k.name),
                "[[kernel]] '{}' is named twice",
                k.name
            );
            if let Some(t) = k.kernel_timeout {
                crate::units::check_seconds("kernel_timeout", t)
                    .map_err(anyhow::Error::msg)
                    .with_context(|| format!("[[kernel]] '{}'", k.name))?;
            }
            kernels.push(UserKernel {
                name: k.name.clone(),
                variant,
                file: k.file.clone(),
                rays,
                kernel_timeout: k.kernel_timeout,
            });
        }
        let whole = Config { shard: None, budget: None, ..self.clone() };
        Ok(Sweep {
            scenes: self.scenes.clone(),
            rays,
            layouts: LayoutId::all().filter(|l| layouts.contains(l)).collect(),
            baselines: BaselineId::all().filter(|b| baselines.contains(b)).collect(),
            series,
            branchings: self.branchings.clone(),
            layout_branchings: self.layout_branchings.clone(),
            packets: self.packets.clone(),
            packet_branching: self.packet_branching,
            maths,
            params: RayParams { width: self.width, height: self.height, seed: self.seed, ..Default::default() },
            plan: Plan { warmup: self.warmup, repeat: self.repeat, count: true },
            device: (!self.device.is_empty()).then(|| self.device.clone()),
            kernel_timeout: self.kernel_timeout,
            float_controls: self.float_controls,
            kernels,
            shard: self.shard,
            budget: self.budget,
            config_hash: format!("{:016x}", crate::digest::fnv1a(format!("{whole:?}").as_bytes())),
        })
    }
}

/// The ray kinds read so far, so that two spellings of one file (`a/r.npy`, `a//r.npy`) are
/// one kind under its first spelling: rows name a ray set so.
#[derive(Default)]
struct Kinds(Vec<RayKind>);

impl Kinds {
    fn spelled(&mut self, k: RayKind) -> RayKind {
        match self.0.iter().find(|x| **x == k) {
            Some(first) => first.clone(),
            None => {
                self.0.push(k.clone());
                k
            }
        }
    }
}

/// A checked sweep ([`Config::check`]): every value of its configuration parsed into what it
/// names. The job list ([`super::jobs::list`]) is made from it.
#[derive(Clone, Debug)]
pub struct Sweep {
    pub scenes: Vec<PathBuf>,
    /// The ray kinds every target is swept over, as configured.
    pub rays: Vec<RayKind>,
    /// The layouts named, in registry order.
    pub layouts: Vec<LayoutId>,
    /// The baselines named, in their list's order.
    pub baselines: Vec<BaselineId>,
    /// The layouts that get the B and P series.
    pub series: Vec<LayoutId>,
    pub branchings: Vec<usize>,
    pub layout_branchings: Vec<usize>,
    pub packets: Vec<usize>,
    pub packet_branching: usize,
    /// The math modes named.
    pub maths: Vec<Math>,
    /// Image size and seed of every generated ray set.
    pub params: RayParams,
    /// How every job is measured: warm-up and timed dispatches, with the counting pass.
    pub plan: Plan,
    /// Vulkan device index or name substring (`None`: the default device).
    pub device: Option<String>,
    pub kernel_timeout: f64,
    pub float_controls: FcChoice,
    pub kernels: Vec<UserKernel>,
    pub shard: Option<Shard>,
    pub budget: Option<f64>,
    /// A hash of the configuration without its shard and budget: which sweep a shard is of.
    pub config_hash: String,
}

/// A checked `[[kernel]]` table.
#[derive(Clone, Debug, PartialEq)]
pub struct UserKernel {
    /// The `kernel` column of its rows.
    pub name: String,
    /// The variant whose built-in kernel it stands in for.
    pub variant: Variant,
    pub file: PathBuf,
    /// Its ray kinds (`None`: the sweep's).
    pub rays: Option<Vec<RayKind>>,
    /// Its own hang timeout in seconds (`None`: the sweep's).
    pub kernel_timeout: Option<f64>,
}

impl Sweep {
    /// Every ray kind of the sweep: the configured ones, then any a user kernel adds.
    pub fn kinds(&self) -> Vec<RayKind> {
        let mut k = self.rays.clone();
        for r in self.kernels.iter().flat_map(|u| u.rays.iter().flatten()) {
            if !k.contains(r) {
                k.push(r.clone());
            }
        }
        k
    }

    /// The math modes swept for a layout: those named that it has (in its order), else its
    /// default.
    pub fn maths_of(&self, layout: LayoutId) -> Vec<Math> {
        let m: Vec<Math> = layout.info().maths.iter().copied().filter(|m| self.maths.contains(m)).collect();
        if m.is_empty() {
            vec![layout.default_math()]
        } else {
            m
        }
    }

    /// The variants: every layout × its maths × `layout_branchings` at P = 1, and for the
    /// `series` layouts also the B series at P = 1 and the P series at `packet_branching`;
    /// sorted (so each layout and B is contiguous).
    pub fn variants(&self) -> Vec<Variant> {
        crate::variant::series(&crate::variant::Series {
            layouts: &self.layouts,
            maths: &|l| self.maths_of(l),
            series: &self.series,
            branchings: &self.branchings,
            layout_branchings: &self.layout_branchings,
            packets: &self.packets,
            packet_branching: self.packet_branching,
        })
    }
}
