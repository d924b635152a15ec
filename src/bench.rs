//! `halftrace bench`: the speed ratios a kernel change is judged by, in one run, in minutes.
//!
//! On each scene and ray kind it validates every target once (our kernels against the CPU
//! reference of the same layout and packet size, hits bit for bit; `rq`, `rt` and `embree`
//! against the f32 reference, reported as agreement), then times them in `rounds` interleaved rounds
//! (every target once per round, each time 1 warm-up and `repeat` timed dispatches, the
//! round's value their median), so slow drift on a shared machine hits every target alike. A
//! ratio "a ÷ b" is speed (rays per second) of a over b, computed per round from the two
//! medians of that round; the table gives the median of those per-round ratios and their min
//! and max. Speed goals live here (and in the closing notes), never in timed unit tests.

use crate::base::Status;
use crate::baseline::BaselineId;
use crate::gpu::{ContextOptions, Gpu};
use crate::layout::LayoutId;
use crate::precision::Math;
use crate::rays::{RayKind, RayParams};
use crate::runner::{Options, Plan, RaySetId, RaySpec, Runner, Target, Timing};
use crate::variant::Variant;
use anyhow::Context;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

/// What `halftrace bench` runs.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    pub scenes: Vec<PathBuf>,
    pub kinds: Vec<RayKind>,
    pub width: u32,
    pub height: u32,
    pub rounds: usize,
    pub repeat: usize,
    pub device: Option<String>,
    pub validation: bool,
    /// Reduced-precision layouts to time beside f32 (empty: every conservative one).
    pub layouts: Vec<LayoutId>,
    /// Branching factors of the P = 1 variants (f32 and the reduced layouts); the fixed ratios
    /// at B = 8 need 8 among them.
    pub branchings: Vec<usize>,
}

/// The packet sizes of the packet ratios (against P = 1), f32 at B = 4 on primary rays.
pub const BENCH_PACKETS: [usize; 5] = [4, 8, 16, 32, 64];

/// What is timed: a built-in variant (float controls as the device has them) or a baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Key {
    Variant(Variant),
    Baseline(BaselineId),
}

impl Key {
    fn label(&self) -> String {
        match self {
            Key::Variant(v) => v.name(false),
            Key::Baseline(b) => b.name().to_string(),
        }
    }

    fn target(&self) -> Target {
        match self {
            Key::Variant(v) => Target::builtin(*v),
            Key::Baseline(b) => Target::Baseline(*b),
        }
    }
}

/// One ratio line of the report.
#[derive(Clone, Debug)]
pub struct Ratio {
    pub what: String,
    pub scene: String,
    pub rays: String,
    /// The two timed things, "a ÷ b".
    pub pair: String,
    pub ratio: Timing,
    /// The goal this ratio is held to (`>= goal`), if any.
    pub goal: Option<f64>,
}

/// The result of a run: every ratio, and every timed thing's Mrays/s.
pub struct BenchResult {
    pub device: String,
    pub ratios: Vec<Ratio>,
    /// (scene, rays, label) → Mrays/s over the rounds (median, min, max).
    pub speeds: Vec<(String, String, String, f64, f64, f64)>,
}

/// The variants timed on every scene and ray kind: the f32 baseline and every conservative
/// reduced-precision layout (or those of `only`) in every math at each of `branchings` (P = 1);
/// on primary rays also f32 at B = 4 with every packet size.
fn variants(kind: &RayKind, only: &[LayoutId], branchings: &[usize]) -> Vec<Variant> {
    let layouts: Vec<LayoutId> = LayoutId::all()
        .filter(|&l| l == LayoutId::f32() || if only.is_empty() { l.info().conservative } else { only.contains(&l) })
        .collect();
    let f32_packets = if *kind == RayKind::Primary { &[LayoutId::f32()][..] } else { &[] };
    crate::variant::series(&crate::variant::Series {
        layouts: &layouts,
        maths: &|l| l.info().maths.to_vec(),
        series: f32_packets,
        branchings: &[],
        layout_branchings: branchings,
        packets: &BENCH_PACKETS,
        packet_branching: 4,
    })
}

/// A ray set of a scene: its kind and size.
struct RaySet {
    kind: RayKind,
    count: usize,
}

/// Runs the benchmark, printing progress to stderr; returns the ratios.
pub fn run(cfg: &BenchConfig) -> anyhow::Result<BenchResult> {
    anyhow::ensure!(!cfg.scenes.is_empty(), "bench: no scene");
    anyhow::ensure!(cfg.rounds >= 1 && cfg.repeat >= 1, "bench: --rounds and --repeat must be at least 1");
    let g = Gpu::new(&ContextOptions { device: cfg.device.clone(), validation: cfg.validation, ..Default::default() })?;
    let device = format!("{} ({})", g.info.name, g.info.driver);
    eprintln!(
        "bench: device {device}; {} rounds of 1 warm-up + {} timed dispatches per target",
        cfg.rounds, cfg.repeat
    );
    let baselines: Vec<BaselineId> = BaselineId::all().collect();
    let mut runner = Runner::new(Some(&g), &baselines, Options { retime: true, ..Default::default() })?;
    let mut ratios = Vec::new();
    let mut speeds = Vec::new();
    let mut largest = (0usize, String::new());
    // Per scene: (scene name, per (kind, key) the per-round medians in ms).
    let mut per_scene: Vec<(String, Vec<RaySet>, Times)> = Vec::new();
    for path in &cfg.scenes {
        let (scene, _) = runner.scene(path).with_context(|| format!("bench: {}", path.display()))?;
        let (name, n) = (scene.name.clone(), scene.len());
        eprintln!("bench: scene {name} ({n} triangles)");
        if n > largest.0 {
            largest = (n, name.clone());
        }
        let (sets, times) = bench_scene(&mut runner, cfg, &name)?;
        per_scene.push((name, sets, times));
    }
    for (name, sets, times) in &per_scene {
        for (ki, set) in sets.iter().enumerate() {
            let n = set.count;
            let t = |k: &Key| times.get(&(ki, *k));
            for ((_, k), ms) in times.iter().filter(|((kk, _), _)| *kk == ki) {
                let s = Timing::of(&ms.iter().map(|m| n as f64 / m / 1e3).collect::<Vec<_>>());
                speeds.push((name.clone(), set.kind.to_string(), k.label(), s.median, s.min, s.max));
            }
            let ratio = |a: &Key, b: &Key| -> Option<Timing> {
                let (ta, tb) = (t(a)?, t(b)?);
                Some(Timing::of(&ta.iter().zip(tb).map(|(x, y)| y / x).collect::<Vec<_>>()))
            };
            let mut push = |what: &str, a: &Key, b: &Key, goal: Option<f64>| {
                if let Some(r) = ratio(a, b) {
                    ratios.push(Ratio {
                        what: what.into(),
                        scene: name.clone(),
                        rays: set.kind.to_string(),
                        pair: format!("{} ÷ {}", a.label(), b.label()),
                        ratio: r,
                        goal,
                    });
                }
            };
            let f32_ = |b: usize, p: usize| Key::Variant(Variant::new(LayoutId::f32(), b, p));
            let f16h = LayoutId::parse("f16h").expect("registered");
            let hv = |m: Math| Key::Variant(Variant::new(f16h, 8, 1).with_math(m));
            push("f16h fp32-math ÷ f32, B = 8, P = 1", &hv(Math::F32), &f32_(8, 1), Some(0.9));
            push("f16h fp16-math ÷ f32, B = 8, P = 1", &hv(Math::F16), &f32_(8, 1), Some(0.35));
            // f16h in each math at the other branching factors timed (no goal).
            for &b in cfg.branchings.iter().filter(|&&b| b != 8) {
                for m in f16h.info().maths {
                    let a = Key::Variant(Variant::new(f16h, b, 1).with_math(*m));
                    let math = match m {
                        Math::F16 => "fp16",
                        Math::F32 => "fp32",
                        Math::Mixed => "mixed",
                    };
                    push(&format!("f16h {math}-math ÷ f32, B = {b}, P = 1"), &a, &f32_(b, 1), None);
                }
            }
            // The best reduced-precision variant against f32 at the same B, by median ratio.
            let mut best: Option<(Key, Key, f64)> = None;
            for (kk, k) in times.keys() {
                if let (true, Key::Variant(v)) = (*kk == ki, k) {
                    if v.layout != LayoutId::f32() && v.packet == 1 {
                        if let Some(r) = ratio(k, &f32_(v.branching, 1)) {
                            if best.as_ref().is_none_or(|b| r.median > b.2) {
                                best = Some((*k, f32_(v.branching, 1), r.median));
                            }
                        }
                    }
                }
            }
            let largest_scene = *name == largest.1;
            if let Some((a, b, _)) = best {
                let what = if largest_scene {
                    "best reduced-precision ÷ f32 (same B), largest scene"
                } else {
                    "best reduced-precision ÷ f32 (same B)"
                };
                push(what, &a, &b, largest_scene.then_some(1.1));
            }
            // The best of ours (any variant) against the host CPU's Embree.
            let embree = BaselineId::parse("embree").map(Key::Baseline);
            let ours: Vec<Key> =
                times.keys().filter(|(kk, k)| *kk == ki && matches!(k, Key::Variant(_))).map(|(_, k)| *k).collect();
            let best_of = |against: &Key| -> Option<Key> {
                ours.iter()
                    .filter_map(|k| Some((*k, ratio(k, against)?.median)))
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|x| x.0)
            };
            if let Some(e) = embree.filter(|e| t(e).is_some()) {
                if let Some(k) = best_of(&e) {
                    push(
                        "best halftrace variant ÷ embree (host CPU)",
                        &k,
                        &e,
                        (set.kind == RayKind::Primary).then_some(0.5),
                    );
                }
            }
            if set.kind == RayKind::Primary {
                for p in BENCH_PACKETS {
                    push(
                        &format!("P = {p} ÷ P = 1, f32, B = 4"),
                        &f32_(4, p),
                        &f32_(4, 1),
                        Some(if p == 8 { 1.0 } else { 0.5 }),
                    );
                }
            }
            // f32 at its better B against the driver's traversals: its ray queries, and its
            // ray-tracing pipeline (no goal set for it yet).
            for (name, what, goal) in [
                ("rq", "f32 ÷ rq (driver ray queries)", Some(1.5)),
                ("rt", "f32 ÷ rt (driver ray-tracing pipeline)", None),
            ] {
                let Some(q) = BaselineId::parse(name).map(Key::Baseline).filter(|q| t(q).is_some()) else { continue };
                let b = [4, 8].into_iter().max_by(|&x, &y| {
                    let m = |b| ratio(&f32_(b, 1), &q).map(|r| r.median).unwrap_or(0.0);
                    m(x).total_cmp(&m(y))
                });
                if let Some(b) = b {
                    push(what, &f32_(b, 1), &q, goal);
                }
            }
        }
    }
    Ok(BenchResult { device, ratios, speeds })
}

type Times = BTreeMap<(usize, Key), Vec<f64>>;

/// Validates every timed thing on the current scene once, then times them in interleaved
/// rounds; returns the ray sets and, per (set, key), the per-round medians (ms).
fn bench_scene(runner: &mut Runner, cfg: &BenchConfig, scene: &str) -> anyhow::Result<(Vec<RaySet>, Times)> {
    let mut sets: Vec<(RaySetId, RaySet)> = Vec::new();
    for kind in &cfg.kinds {
        let params = RayParams { width: cfg.width, height: cfg.height, ..Default::default() };
        let id = runner.ray_set(&RaySpec { kind: kind.clone(), params })?;
        sets.push((id, RaySet { kind: kind.clone(), count: runner.rays(id).rays.len() }));
    }
    let mut keys: Vec<(usize, Key)> = Vec::new();
    for (ki, (_, s)) in sets.iter().enumerate() {
        keys.extend(variants(&s.kind, &cfg.layouts, &cfg.branchings).into_iter().map(|v| (ki, Key::Variant(v))));
        keys.extend(BaselineId::all().map(|b| (ki, Key::Baseline(b))));
    }
    // Validated once, each against its reference (ours: the CPU reference; baselines: f32).
    let validate = Plan { warmup: 0, repeat: 0, count: false };
    let mut timed = Vec::new();
    for (ki, key) in keys {
        let (id, set) = &sets[ki];
        let o = runner.measure(&key.target(), *id, validate)?;
        match &o.status {
            Status::Ok => timed.push((ki, key)),
            Status::Skipped(why) => eprintln!("bench: {} skipped: {why}", key.label()),
            Status::Failed(f) => anyhow::bail!("bench: {scene} {}: {f}", set.kind),
        }
        if let (Key::Baseline(b), Status::Ok) = (key, &o.status) {
            let a = o.m.vs_f32;
            eprintln!(
                "bench: {scene} {} {b}: agrees with f32 on {:.4}% of {} rays",
                set.kind,
                100.0 * a.rate(),
                a.total
            );
        }
    }
    eprintln!("bench: {scene}: {} targets validated", timed.len());
    let mut times: Times = BTreeMap::new();
    let plan = Plan { warmup: 1, repeat: cfg.repeat, count: false };
    for round in 0..cfg.rounds {
        for (ki, key) in &timed {
            let o = runner.measure(&key.target(), sets[*ki].0, plan)?;
            let t = o.m.timing.ok_or_else(|| anyhow::anyhow!("bench: {scene} {}: {}", key.label(), o.status))?;
            times.entry((*ki, *key)).or_default().push(t.median);
        }
        eprintln!("bench: {scene}: round {}/{} done", round + 1, cfg.rounds);
    }
    Ok((sets.into_iter().map(|(_, s)| s).collect(), times))
}

/// The report: the ratios (with their goals) and every target's speed, as Markdown.
pub fn markdown(cfg: &BenchConfig, r: &BenchResult) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# halftrace bench\n\ndevice: {}; rays {}×{} per kind; {} rounds, each 1 warm-up + {} timed dispatches per \
         target (a round's value: their median); ratios are speed ratios computed per round, shown as median \
         (min–max) over the rounds.\n",
        r.device, cfg.width, cfg.height, cfg.rounds, cfg.repeat
    );
    md += "| ratio | scene | rays | a ÷ b | median | min | max | goal | met |\n|---|---|---|---|---:|---:|---:|---:|---|\n";
    for x in &r.ratios {
        let (t, met) = match x.goal {
            Some(t) => (format!("≥ {t}"), if x.ratio.median >= t { "yes" } else { "**no**" }),
            None => ("–".into(), ""),
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {t} | {met} |",
            x.what, x.scene, x.rays, x.pair, x.ratio.median, x.ratio.min, x.ratio.max
        );
    }
    md += "\n| scene | rays | kernel | Mrays/s median | min | max |\n|---|---|---|---:|---:|---:|\n";
    for (s, k, t, med, lo, hi) in &r.speeds {
        let _ = writeln!(md, "| {s} | {k} | {t} | {med:.2} | {lo:.2} | {hi:.2} |");
    }
    md
}
