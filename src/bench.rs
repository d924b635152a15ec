//! `halftrace bench`: the speed ratios a kernel change is judged by, in one run, in minutes.
//!
//! On each scene and ray kind it validates every target once (our kernels against the CPU
//! reference of the same layout and packet size, hits bit for bit; `rq` and `embree` against
//! the f32 reference, reported as agreement), then times them in `rounds` interleaved rounds
//! (every target once per round, each time 1 warm-up and `repeat` timed dispatches, the
//! round's value their median), so slow drift on a shared machine hits every target alike. A
//! ratio "a ÷ b" is speed (rays per second) of a over b, computed per round from the two
//! medians of that round; the table gives the median of those per-round ratios and their min
//! and max. Speed targets live here (and in the closing notes), never in timed unit tests.

use crate::bvh::{self, BinaryBvh};
use crate::gpu::kernel::{choose_impl, GpuBvh, Kernel, Source};
use crate::gpu::{self, ContextOptions, Gpu};
use crate::layout::{BaselineDevice, BaselineScene, Encoded, LayoutId, Math};
use crate::measure::{self, BaselineTarget, KernelTarget, Plan, Reference, Target, Timing};
use crate::rays::{make_rays, Ray, RayKind, RayParams};
use crate::scene::{self, Scene};
use crate::trace::Hit;
use crate::variant::{FcChoice, Variant};
use anyhow::Context;
use std::collections::{BTreeMap, HashMap};
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
}

/// The packet sizes of the packet ratios (against P = 1), f32 at B = 4 on primary rays.
pub const BENCH_PACKETS: [usize; 5] = [4, 8, 16, 32, 64];

/// What a timed thing is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Key {
    Variant(Variant),
    Baseline(LayoutId),
}

impl Key {
    fn label(&self) -> String {
        match self {
            Key::Variant(v) => v.name(false),
            Key::Baseline(b) => b.name().to_string(),
        }
    }
}

/// One ratio line of the report.
#[derive(Clone, Debug)]
pub struct Ratio {
    pub what: String,
    pub scene: String,
    pub rays: String,
    /// The two targets, "a ÷ b".
    pub pair: String,
    pub ratio: Timing,
    /// The target this ratio is held to (`>= target`), if any.
    pub target: Option<f64>,
}

/// The result of a run: every ratio, and every target's Mrays/s.
pub struct BenchResult {
    pub device: String,
    pub ratios: Vec<Ratio>,
    /// (scene, rays, target label) → Mrays/s over the rounds (median, min, max).
    pub speeds: Vec<(String, String, String, f64, f64, f64)>,
}

/// The variants timed on every scene and ray kind: the f32 baseline at B = 4 and 8, every
/// conservative reduced-precision layout (or those of `only`) in every math at B = 4 and 8
/// (P = 1); on primary rays also f32 at B = 4 with every packet size.
fn variants(kind: &RayKind, only: &[LayoutId]) -> Vec<Variant> {
    let mut v = Vec::new();
    for layout in LayoutId::layouts() {
        let l = layout.bvh().expect("a BVH layout");
        let chosen =
            layout == LayoutId::f32() || if only.is_empty() { l.conservative() } else { only.contains(&layout) };
        if !chosen {
            continue;
        }
        for &math in l.maths() {
            for b in [4, 8] {
                v.push(Variant::new(layout, b, 1).with_math(math));
            }
        }
    }
    if *kind == RayKind::Primary {
        for p in BENCH_PACKETS {
            v.push(Variant::new(LayoutId::f32(), 4, p));
        }
    }
    v
}

struct RaySet {
    kind: RayKind,
    rays: Vec<Ray>,
    f32_hits: Vec<Hit>,
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
    let mut base_devs: Vec<(LayoutId, Box<dyn BaselineDevice + '_>)> = Vec::new();
    for b in LayoutId::all().filter(|l| l.baseline().is_some()) {
        let bl = b.baseline().expect("a baseline");
        match bl.unavailable(&g.info) {
            Some(why) => eprintln!("bench: {b} skipped: {why}"),
            None => base_devs.push((b, bl.prepare(&g).with_context(|| format!("baseline {b}"))?)),
        }
    }
    let mut kernels: HashMap<Variant, Kernel> = HashMap::new();
    let mut ratios = Vec::new();
    let mut speeds = Vec::new();
    let mut largest = (0usize, String::new());
    // Per scene: (scene name, per (kind, key) the per-round medians in ms).
    let mut per_scene: Vec<(String, Vec<RaySet>, Times)> = Vec::new();
    for path in &cfg.scenes {
        let scene = scene::load(path).with_context(|| format!("bench: {}", path.display()))?;
        let bin = bvh::build_binary(&scene);
        eprintln!("bench: scene {} ({} triangles)", scene.name, scene.len());
        if scene.len() > largest.0 {
            largest = (scene.len(), scene.name.clone());
        }
        let (sets, times) = bench_scene(&g, cfg, &scene, &bin, &base_devs, &mut kernels)?;
        per_scene.push((scene.name.clone(), sets, times));
    }
    for (name, sets, times) in &per_scene {
        for (ki, set) in sets.iter().enumerate() {
            let n = set.rays.len();
            let t = |k: &Key| times.get(&(ki, *k));
            for ((_, k), ms) in times.iter().filter(|((kk, _), _)| *kk == ki) {
                let s = Timing::of(&ms.iter().map(|m| n as f64 / m / 1e3).collect::<Vec<_>>());
                speeds.push((name.clone(), set.kind.to_string(), k.label(), s.median, s.min, s.max));
            }
            let ratio = |a: &Key, b: &Key| -> Option<Timing> {
                let (ta, tb) = (t(a)?, t(b)?);
                Some(Timing::of(&ta.iter().zip(tb).map(|(x, y)| y / x).collect::<Vec<_>>()))
            };
            let mut push = |what: &str, a: &Key, b: &Key, target: Option<f64>| {
                if let Some(r) = ratio(a, b) {
                    ratios.push(Ratio {
                        what: what.into(),
                        scene: name.clone(),
                        rays: set.kind.to_string(),
                        pair: format!("{} ÷ {}", a.label(), b.label()),
                        ratio: r,
                        target,
                    });
                }
            };
            let f32_ = |b: usize, p: usize| Key::Variant(Variant::new(LayoutId::f32(), b, p));
            let f16h = LayoutId::parse("f16h").expect("registered");
            let hv = |m: Math| Key::Variant(Variant::new(f16h, 8, 1).with_math(m));
            push("f16h fp32-math ÷ f32, B = 8, P = 1", &hv(Math::F32), &f32_(8, 1), Some(0.9));
            push("f16h fp16-math ÷ f32, B = 8, P = 1", &hv(Math::F16), &f32_(8, 1), Some(0.35));
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
            let embree = LayoutId::parse("embree").ok().map(Key::Baseline);
            let rq = LayoutId::parse("rq").ok().map(Key::Baseline);
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
            if let Some(q) = rq.filter(|q| t(q).is_some()) {
                // f32 at its better B against the driver's ray queries.
                let b = [4, 8].into_iter().max_by(|&x, &y| {
                    let m = |b| ratio(&f32_(b, 1), &q).map(|r| r.median).unwrap_or(0.0);
                    m(x).total_cmp(&m(y))
                });
                if let Some(b) = b {
                    push("f32 ÷ rq (driver ray queries)", &f32_(b, 1), &q, Some(1.5));
                }
            }
        }
    }
    Ok(BenchResult { device, ratios, speeds })
}

type Times = BTreeMap<(usize, Key), Vec<f64>>;

fn bench_scene<'g>(
    g: &'g Gpu,
    cfg: &BenchConfig,
    scene: &Scene,
    bin: &BinaryBvh,
    base_devs: &[(LayoutId, Box<dyn BaselineDevice + 'g>)],
    kernels: &mut HashMap<Variant, Kernel<'g>>,
) -> anyhow::Result<(Vec<RaySet>, Times)> {
    let f32_enc = Encoded::new(scene, bin, LayoutId::f32(), 4)?;
    let mut sets = Vec::new();
    for kind in &cfg.kinds {
        let params = RayParams { width: cfg.width, height: cfg.height, ..Default::default() };
        let rays = make_rays(scene, bin, kind, &params)?;
        let f32_hits = f32_enc.trace_default(&rays).0;
        sets.push(RaySet { kind: kind.clone(), rays, f32_hits });
    }
    // Encodings, kernels and baseline structures for everything timed on this scene.
    let mut wanted: Vec<(usize, Variant)> = Vec::new();
    for (ki, s) in sets.iter().enumerate() {
        for v in variants(&s.kind, &cfg.layouts) {
            match gpu::support::resolve(&g.info, v, FcChoice::Auto) {
                Ok(v) => wanted.push((ki, v)),
                Err(why) => eprintln!("bench: {} skipped: {why}", v.name(false)),
            }
        }
    }
    let mut encs: BTreeMap<(LayoutId, usize), (Encoded, GpuBvh)> = BTreeMap::new();
    for (_, v) in &wanted {
        if let std::collections::btree_map::Entry::Vacant(slot) = encs.entry((v.layout, v.branching)) {
            let e = Encoded::new(scene, bin, v.layout, v.branching)?;
            let gb = GpuBvh::upload(g, &e).with_context(|| format!("{}, B={}", v.layout, v.branching))?;
            slot.insert((e, gb));
        }
        // A scene beyond one storage buffer is read by address: kernels are kept per build.
        let kv = v.with_buffers(encs[&(v.layout, v.branching)].1.buffers);
        if let std::collections::hash_map::Entry::Vacant(slot) = kernels.entry(kv) {
            slot.insert(
                Kernel::build(g, &kv, choose_impl(g, v, None), false, &Source::Builtin)
                    .with_context(|| v.name(false))?,
            );
        }
    }
    let mut base_scenes: Vec<(LayoutId, Box<dyn BaselineScene + '_>)> = Vec::new();
    for (b, dev) in base_devs {
        base_scenes.push((*b, dev.scene(scene).with_context(|| format!("baseline {b} on {}", scene.name))?));
    }
    // The targets, validated once.
    let mut targets: Vec<(usize, Key, Box<dyn Target + '_>)> = Vec::new();
    for (ki, v) in &wanted {
        let (_, gb) = &encs[&(v.layout, v.branching)];
        let timed = &kernels[&v.with_buffers(gb.buffers)];
        targets.push((*ki, Key::Variant(*v), Box::new(KernelTarget { gpu: g, bvh: gb, timed, counting: None })));
    }
    for ki in 0..sets.len() {
        for (b, bs) in &base_scenes {
            targets.push((ki, Key::Baseline(*b), Box::new(BaselineTarget { name: b.name(), scene: bs.as_ref() })));
        }
    }
    let one = Plan { warmup: 0, repeat: 1, count: false };
    for (ki, key, t) in &targets {
        let set = &sets[*ki];
        let m = match key {
            Key::Variant(v) => {
                let (enc, _) = &encs[&(v.layout, v.branching)];
                let (hits, counters) = enc.trace_fc(&set.rays, v.packet, v.math, v.fc);
                measure::validate_then_time(
                    t.as_ref(),
                    &set.rays,
                    Reference::Exact { hits: &hits, counters: &counters },
                    &set.f32_hits,
                    one,
                )?
            }
            Key::Baseline(b) => {
                let m = measure::validate_then_time(t.as_ref(), &set.rays, Reference::Agreement, &set.f32_hits, one)?;
                eprintln!(
                    "bench: {} {} {b}: agrees with f32 on {:.4}% of {} rays",
                    scene.name,
                    set.kind,
                    100.0 * m.vs_f32.rate(),
                    m.vs_f32.total
                );
                m
            }
        };
        if let Some(f) = m.failure {
            anyhow::bail!("bench: {} {}: {f}", scene.name, set.kind);
        }
    }
    eprintln!("bench: {}: {} targets validated", scene.name, targets.len());
    let mut times: Times = BTreeMap::new();
    for round in 0..cfg.rounds {
        for (ki, key, t) in &targets {
            let out = t.dispatch(&sets[*ki].rays, 1, cfg.repeat)?;
            times.entry((*ki, *key)).or_default().push(Timing::of(&out.times_ms).median);
        }
        eprintln!("bench: {}: round {}/{} done", scene.name, round + 1, cfg.rounds);
    }
    drop(targets);
    Ok((sets, times))
}

/// The report: the ratios (with targets) and every target's speed, as Markdown.
pub fn markdown(cfg: &BenchConfig, r: &BenchResult) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# halftrace bench\n\ndevice: {}; rays {}×{} per kind; {} rounds, each 1 warm-up + {} timed dispatches per target (a round's value: their median); ratios are speed ratios computed per round, shown as median (min–max) over the rounds.\n", r.device, cfg.width, cfg.height, cfg.rounds, cfg.repeat);
    md += "| ratio | scene | rays | a ÷ b | median | min | max | target | met |\n|---|---|---|---|---:|---:|---:|---:|---|\n";
    for x in &r.ratios {
        let (t, met) = match x.target {
            Some(t) => (format!("≥ {t}"), if x.ratio.median >= t { "yes" } else { "**no**" }),
            None => ("–".into(), ""),
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {t} | {met} |",
            x.what, x.scene, x.rays, x.pair, x.ratio.median, x.ratio.min, x.ratio.max
        );
    }
    md += "\n| scene | rays | target | Mrays/s median | min | max |\n|---|---|---|---:|---:|---:|\n";
    for (s, k, t, med, lo, hi) in &r.speeds {
        let _ = writeln!(md, "| {s} | {k} | {t} | {med:.2} | {lo:.2} | {hi:.2} |");
    }
    md
}
