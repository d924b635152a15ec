//! `device-report.json`: what each run and step recorded, and whether a step is finished
//! (recorded and its files present).

use super::*;

/// The record of a report folder (`device-report.json`).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct State {
    pub device: String,
    pub driver: String,
    pub kind: String,
    pub api_version: String,
    pub version: String,
    pub commit: String,
    pub scenes: Vec<String>,
    pub width: u32,
    pub height: u32,
    /// One entry per run of the command (a resumed report has several).
    pub runs: Vec<RunRecord>,
    /// Finished steps by name.
    pub steps: BTreeMap<String, StepRecord>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct RunRecord {
    pub started_unix: u64,
    pub budget_s: f64,
    pub seconds: f64,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StepRecord {
    /// `ok`, `failed (exit N)`, `skipped: why`, `partial: …`, `stopped: …`.
    pub status: String,
    pub seconds: f64,
    /// Finished: a resumed report does not run it again.
    pub done: bool,
    pub output: String,
}

pub(super) const STATE: &str = "device-report.json";
/// The steps, in the order they run.
pub const STEPS: &[&str] = &["devices", "conformance", "bench", "sweep", "isa"];
/// The names this command writes in its folder (what `--force` replaces; nothing else there is
/// touched).
pub(super) const OWN: &[&str] = &[
    STATE,
    "report.md",
    "devices.txt",
    "vulkaninfo.txt",
    "nvidia-smi.txt",
    "bench.md",
    "logs",
    "conformance",
    "sweep",
    "scenes",
];

/// What the report writes into its folder: the folder is its alone, `--resume` continues from
/// its state, `--force` replaces only [`OWN`].
pub(super) const OUTPUTS: Outputs = Outputs {
    command: "device-report",
    owns: |n| OWN.contains(&n),
    folders: &["logs", "conformance", "sweep", "scenes"],
    alone: true,
    resume: Some((STATE, "finish the report there")),
    force: true,
};

/// Readies the claimed folder: new (empty), a report of the same device and settings to
/// resume, or one whose own files `--force` replaces; returns the state to continue from.
pub(super) fn prepare(
    out: &Claimed,
    dev: &DeviceInfo,
    scenes: &[String],
    (width, height): (u32, u32),
) -> anyhow::Result<State> {
    let fresh = State {
        device: dev.name.clone(),
        driver: dev.driver.clone(),
        kind: dev.kind.clone(),
        api_version: dev.api_version.clone(),
        version: env!("CARGO_PKG_VERSION").into(),
        commit: env!("HALFTRACE_COMMIT").into(),
        scenes: scenes.to_vec(),
        width,
        height,
        ..Default::default()
    };
    if !out.resumes() {
        out.replace_own()?;
        return Ok(fresh);
    }
    let path = out.path().join(STATE);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("--resume: {} is not a device report (no readable {STATE})", out.path().display()))?;
    let old: State = serde_json::from_str(&text).with_context(|| format!("--resume: {}", path.display()))?;
    for (what, was, now) in [
        ("device", old.device.clone(), fresh.device.clone()),
        ("driver", old.driver.clone(), fresh.driver.clone()),
        ("scenes", old.scenes.join(", "), fresh.scenes.join(", ")),
        ("image size", format!("{}x{}", old.width, old.height), format!("{}x{}", fresh.width, fresh.height)),
    ] {
        anyhow::ensure!(
            was == now,
            "--resume: {} is a report with {what} {was}, not {now}; resume with the same settings, or choose another \
             folder",
            out.path().display()
        );
    }
    Ok(old)
}

/// The files each step writes, relative to the report's folder (the first is the one its row
/// in report.md links to).
pub(super) fn outputs(step: &str) -> &'static [&'static str] {
    match step {
        "devices" => &["devices.txt"],
        "conformance" => &["conformance/conformance.md", "conformance/conformance.csv"],
        "bench" => &["bench.md"],
        "sweep" => &["sweep/report.md", "sweep/results.csv"],
        "isa" => &["sweep/isa.md", "sweep/isa.json"],
        _ => &[],
    }
}

/// A file of a step recorded as finished that is not there (deleted since, or never written
/// by a step that failed): the record is not trusted, the step runs again.
pub(super) fn missing(state: &State, out: &Path, step: &str) -> Option<&'static str> {
    state.steps.get(step).filter(|s| s.done && !s.status.starts_with("skipped"))?;
    outputs(step).iter().copied().find(|f| !out.join(f).is_file())
}

/// Whether a step is finished: recorded so, with its files there (a resumed report does not
/// run it again).
pub(super) fn finished(state: &State, out: &Path, step: &str) -> bool {
    state.steps.get(step).is_some_and(|s| s.done) && missing(state, out, step).is_none()
}

pub(super) fn save(out: &Path, state: &State) -> anyhow::Result<()> {
    crate::fsx::write_atomic(&out.join(STATE), serde_json::to_string_pretty(state)?.as_bytes())
}

pub(super) fn record(state: &mut State, name: &str, mut r: StepRecord) {
    r.output = outputs(name)[0].into();
    state.steps.insert(name.into(), r);
}
