//! Validate, then time — the one way every kernel, user kernel and baseline is measured. A
//! tracer's hits are first compared with a reference (for our layouts the CPU reference of
//! the same layout, packet size, math and float controls: hits bit for bit, equal to the f32
//! reference's for a conservative layout, then the counting kernel's hits and counters);
//! only a tracer that passes is timed: `warmup` untimed then `repeat` timed dispatches,
//! summarised as median, min and max.

use crate::base::{agreement, Agreement, Counters, Hit, Ray, RunOutput};

/// With float controls off, a device may round box-test arithmetic differently from the CPU
/// reference (the bounds stay conservative, so hits are exact): counters may then differ on at
/// most this fraction of a ray set's rays.
pub const FC_OFF_COUNTER_BOUND: f64 = 0.01;

/// Median, min and max of repeated timings (ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Timing {
    /// Summarises at least one timing.
    pub fn of(times_ms: &[f64]) -> Timing {
        let mut t = times_ms.to_vec();
        t.sort_by(f64::total_cmp);
        Timing { median: t[t.len() / 2], min: t[0], max: t[t.len() - 1], count: t.len() }
    }

    /// Mrays/s of `rays` at the median, the slowest and the fastest timing.
    pub fn mrays(&self, rays: usize) -> (f64, f64, f64) {
        let n = rays.max(1) as f64;
        (n / self.median / 1e3, n / self.max / 1e3, n / self.min / 1e3)
    }
}

/// Something that traces rays: a kernel on a device (with its counting kernel) or a baseline.
pub trait Tracer {
    /// Names the tracer in messages (the kernel, and the user's file if it is theirs).
    fn label(&self) -> String;
    /// `warmup` untimed then `repeat` timed traversals (at least one in all).
    fn dispatch(&self, rays: &[Ray], warmup: usize, repeat: usize) -> anyhow::Result<RunOutput>;
    /// The counting pass (hits and counters), when the tracer has one.
    fn count(&self, rays: &[Ray]) -> Option<anyhow::Result<RunOutput>>;
}

/// What a tracer's results are checked against before it is timed.
pub enum Reference<'a> {
    /// The CPU reference of the same layout, packet size, math and float controls: hits bit
    /// for bit (and equal to the f32 reference's when `conservative`), counters exactly on
    /// all but `counter_slack` rays.
    Exact { hits: &'a [Hit], counters: &'a [Counters], conservative: bool, counter_slack: usize },
    /// Nothing exact (a baseline with its own triangle test): its agreement with the f32
    /// reference is measured and reported, never a failure.
    Agreement,
}

/// How to measure.
#[derive(Clone, Copy, Debug)]
pub struct Plan {
    pub warmup: usize,
    /// Timed dispatches; 0: validate only.
    pub repeat: usize,
    /// Run the counting pass (when the tracer has one) and check its counters.
    pub count: bool,
}

impl Plan {
    /// Validation alone, counters included.
    pub const VALIDATE: Plan = Plan { warmup: 0, repeat: 0, count: true };
}

/// The outcome of [`validate_then_time`].
#[derive(Clone, Debug)]
pub struct Measurement {
    pub hits: Vec<Hit>,
    /// Per-ray counters, when counted.
    pub counters: Option<Vec<Counters>>,
    /// `None` when validation failed or the plan times nothing.
    pub timing: Option<Timing>,
    /// Why validation failed, naming the tracer, the ray and both results.
    pub failure: Option<String>,
    /// Agreement with the f32 reference: the one definition of "differs from f32".
    pub vs_f32: Agreement,
    /// Rays whose counters differed from the reference (within the allowed slack).
    pub counter_diffs: usize,
    /// Rays the traversal flagged for the exact re-trace (fp32 could not decide them).
    pub flagged: usize,
}

impl Measurement {
    /// Nothing measured: a tracer the device cannot run.
    pub fn none() -> Measurement {
        Measurement {
            hits: Vec::new(),
            counters: None,
            timing: None,
            failure: None,
            vs_f32: agreement(&[], &[]),
            counter_diffs: 0,
            flagged: 0,
        }
    }
}

/// Where `got` and `want` (per-ray `what`: hits or counters) differ, as a message naming the
/// tracer, how many rays, the first ray and both results; `None` when they agree on all but
/// `slack` rays.
#[allow(clippy::too_many_arguments)]
pub fn compare<T: std::fmt::Debug>(
    label: &str,
    what: &str,
    against: &str,
    rays: &[Ray],
    got: &[T],
    want: &[T],
    slack: usize,
    same: impl Fn(&T, &T) -> bool,
) -> Result<usize, String> {
    if got.len() != want.len() {
        return Err(format!("{label}: {} {what} for {} rays, {against} has {}", got.len(), rays.len(), want.len()));
    }
    let bad: Vec<usize> = (0..got.len()).filter(|&i| !same(&got[i], &want[i])).collect();
    match bad.first() {
        Some(&i) if bad.len() > slack => Err(format!(
            "{label}: {} of {} rays differ from {against} in their {what}; first: ray {i} {:?}: got {:?}, {against} {:?}",
            bad.len(),
            got.len(),
            rays[i],
            got[i],
            want[i]
        )),
        _ => Ok(bad.len()),
    }
}

const CPU: &str = "the CPU reference";

/// Validates `tracer` on `rays` against `reference`, then times it as `plan` says (see the
/// module docs). `f32_hits` are the f32 reference's hits, for the agreement every result
/// reports.
pub fn validate_then_time(
    tracer: &dyn Tracer,
    rays: &[Ray],
    reference: Reference,
    f32_hits: &[Hit],
    plan: Plan,
) -> anyhow::Result<Measurement> {
    let label = tracer.label();
    // A conservative layout's CPU reference must be f32's hits before any kernel is compared
    // with it.
    if let Reference::Exact { hits, conservative: true, .. } = reference {
        if let Err(e) = compare(&label, "hits", "the f32 reference", rays, hits, f32_hits, 0, Hit::same_bits) {
            let failure = format!("{e} (its CPU reference: a conservative layout must return the f32 hits)");
            return Ok(Measurement { failure: Some(failure), ..Measurement::none() });
        }
    }
    // Device errors (a hung kernel above all) end the measurement as errors; disagreements
    // are its failure.
    let first = tracer.dispatch(rays, 0, 1)?;
    let vs_f32 = agreement(&first.hits, f32_hits);
    let mut m = Measurement { hits: first.hits, vs_f32, flagged: first.flagged, ..Measurement::none() };
    if let Reference::Exact { hits, counters, counter_slack, .. } = reference {
        if let Err(f) = compare(&label, "hits", CPU, rays, &m.hits, hits, 0, Hit::same_bits) {
            m.failure = Some(f);
            return Ok(m);
        }
        if let Some(c) = if plan.count { tracer.count(rays) } else { None } {
            let c = c?;
            let got = c.counters.expect("a counting pass returns counters");
            let checked = compare(&format!("{label} (counting)"), "hits", CPU, rays, &c.hits, hits, 0, Hit::same_bits)
                .and_then(|_| compare(&label, "counters", CPU, rays, &got, counters, counter_slack, |a, b| a == b));
            m.counters = Some(got);
            match checked {
                Ok(diffs) => m.counter_diffs = diffs,
                Err(f) => {
                    m.failure = Some(f);
                    return Ok(m);
                }
            }
        }
    }
    if plan.repeat > 0 {
        match time(tracer, rays, &m.hits, plan)? {
            Ok(t) => m.timing = Some(t),
            Err(f) => m.failure = Some(f),
        }
    }
    Ok(m)
}

/// The timed dispatches of a tracer already validated against `hits`: `Ok(Err(failure))`
/// when the timed dispatches' hits differ from the validated ones.
pub fn time(tracer: &dyn Tracer, rays: &[Ray], hits: &[Hit], plan: Plan) -> anyhow::Result<Result<Timing, String>> {
    let timed = tracer.dispatch(rays, plan.warmup, plan.repeat.max(1))?;
    Ok(compare(&tracer.label(), "hits", "its first dispatch", rays, &timed.hits, hits, 0, Hit::same_bits)
        .map(|_| Timing::of(&timed.times_ms)))
}
