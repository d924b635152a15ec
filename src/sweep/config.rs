//! A sweep's configuration: `--config sweep.toml` (every key in `sweep.example.toml`) with
//! flags over it, checked when read.

use super::Shard;
use crate::baseline::BaselineId;
use crate::bvh;
use crate::layout::LayoutId;
use crate::precision::{FcChoice, Math};
use crate::rays::RayKind;
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
    pub kernel: Vec<KernelSpec>,
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
pub struct KernelSpec {
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
}

impl KernelSpec {
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
        let b = bvh::check_branching(self.branching.unwrap_or(4)).with_context(what)?;
        let p = self.packet.unwrap_or(1);
        anyhow::ensure!(PACKETS.contains(&p), "{}: packet {p} is not one of 1, 4, 8, 16, 32, 64", what());
        let mut v = Variant::new(layout, b, p);
        if let Some(m) = &self.math {
            let math: Math = m.parse().map_err(anyhow::Error::msg).with_context(what)?;
            anyhow::ensure!(layout.info().maths.contains(&math), "{}: layout {layout} has no math mode {m}", what());
            v = v.with_math(math);
        }
        Ok(v)
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

    /// Checks every value names something that exists.
    pub fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.scenes.is_empty(), "scenes: at least one scene is needed");
        anyhow::ensure!(!self.rays.is_empty(), "rays: at least one ray kind is needed");
        anyhow::ensure!(!self.layouts.is_empty(), "layouts: at least one layout or baseline is needed");
        check_scenes("scenes", &self.scenes)?;
        for r in &self.rays {
            r.parse::<RayKind>()?;
        }
        for l in &self.layouts {
            if BaselineId::parse(l).is_none() {
                l.parse::<LayoutId>().context("layouts")?;
            }
        }
        for l in &self.series {
            l.parse::<LayoutId>().context("series")?;
        }
        for &b in self.branchings.iter().chain(&self.layout_branchings).chain([&self.packet_branching]) {
            bvh::check_branching(b).context("branchings")?;
        }
        for &p in &self.packets {
            anyhow::ensure!(PACKETS.contains(&p), "packets: {p} is not one of 1, 4, 8, 16, 32, 64");
        }
        for m in &self.maths {
            m.parse::<Math>().map_err(anyhow::Error::msg).context("maths")?;
        }
        anyhow::ensure!(self.repeat >= 1, "repeat must be at least 1");
        crate::units::check_seconds("kernel_timeout", self.kernel_timeout).map_err(anyhow::Error::msg)?;
        anyhow::ensure!(self.width > 0 && self.height > 0, "width and height must be positive");
        crate::rays::check_image_size(self.width, self.height).map_err(anyhow::Error::msg)?;
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
            k.variant()?;
            for r in k.rays.iter().flatten() {
                r.parse::<RayKind>().with_context(|| format!("[[kernel]] '{}'", k.name))?;
            }
            anyhow::ensure!(k.file.is_file(), "[[kernel]] '{}': {} is not a readable file", k.name, k.file.display());
            anyhow::ensure!(
                !self.kernel[..i].iter().any(|o| o.name == k.name),
                "[[kernel]] '{}' is named twice",
                k.name
            );
        }
        Ok(())
    }

    /// The layouts named, in registry order.
    pub fn layout_ids(&self) -> Vec<LayoutId> {
        LayoutId::all().filter(|l| self.layouts.iter().any(|n| LayoutId::parse(n) == Ok(*l))).collect()
    }

    /// The baselines named, in their list's order.
    pub fn baselines(&self) -> Vec<BaselineId> {
        BaselineId::all().filter(|b| self.layouts.iter().any(|n| n == b.name())).collect()
    }

    /// The math modes swept for a layout: those named that it has (in its order), else its
    /// default.
    pub fn maths_of(&self, layout: LayoutId) -> Vec<Math> {
        let named: Vec<Math> = self.maths.iter().filter_map(|m| m.parse().ok()).collect();
        let m: Vec<Math> = layout.info().maths.iter().copied().filter(|m| named.contains(m)).collect();
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
        let mut v = Vec::new();
        for layout in self.layout_ids() {
            let series = self.series.iter().any(|s| s == layout.name());
            for math in self.maths_of(layout) {
                for &b in &self.layout_branchings {
                    v.push(Variant::new(layout, b, 1).with_math(math));
                }
                if series {
                    for &b in &self.branchings {
                        v.push(Variant::new(layout, b, 1).with_math(math));
                    }
                    for &p in &self.packets {
                        v.push(Variant::new(layout, self.packet_branching, p).with_math(math));
                    }
                }
            }
        }
        v.sort();
        v.dedup();
        v
    }
}
