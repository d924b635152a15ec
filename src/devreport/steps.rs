//! The steps' child processes: each runs this binary (or a tool beside it) with a time limit,
//! its output streamed to `logs/<step>.log`.

use super::*;

/// How long a step of fixed size (devices, conformance, bench, isa) may run before it is
/// taken for hung and stopped: they run whole, whatever the budget.
pub(super) const HANG: Duration = Duration::from_secs(30 * 60);

/// Runs the steps' child processes.
pub(super) struct Steps<'a> {
    pub(super) exe: &'a Path,
    pub(super) out: &'a Path,
}

impl Steps<'_> {
    /// Runs `exe args`, stopped after `limit`; stderr (and stdout, unless `stdout_file` takes
    /// it) go to `logs/<name>.log`.
    pub(super) fn run(
        &self,
        name: &str,
        args: &[String],
        stdout_file: Option<&str>,
        limit: Duration,
    ) -> anyhow::Result<StepRecord> {
        let log = self.out.join("logs").join(format!("{name}.log"));
        let err = std::fs::File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let stdout = match stdout_file {
            Some(_) => Stdio::piped(),
            None => Stdio::from(err.try_clone()?),
        };
        let mut cmd = Command::new(self.exe);
        cmd.args(args).stdin(Stdio::null()).stdout(stdout).stderr(Stdio::from(err));
        let t0 = Instant::now();
        let mut child = cmd.spawn().with_context(|| format!("starting {} {name}", self.exe.display()))?;
        // Read a captured stdout on a thread (it may exceed a pipe's buffer).
        let reader = child.stdout.take().map(|mut s| {
            std::thread::spawn(move || {
                let mut v = Vec::new();
                let _ = std::io::Read::read_to_end(&mut s, &mut v);
                v
            })
        });
        let status = loop {
            if let Some(s) = child.try_wait()? {
                break Some(s);
            }
            if t0.elapsed() > limit {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        let captured = reader.and_then(|h| h.join().ok());
        if let (Some(file), Some(bytes)) = (stdout_file, &captured) {
            crate::fsx::write_atomic(&self.out.join(file), bytes)?;
        }
        let seconds = t0.elapsed().as_secs_f64();
        Ok(match status {
            Some(s) if s.success() => StepRecord { status: "ok".into(), seconds, done: true, output: String::new() },
            Some(s) => StepRecord {
                status: format!("failed ({}; see logs/{name}.log)", exit_text(s)),
                seconds,
                done: true,
                output: String::new(),
            },
            None => StepRecord {
                status: format!("stopped: still running after {:.0} s (logs/{name}.log)", limit.as_secs_f64()),
                seconds,
                done: false,
                output: String::new(),
            },
        })
    }

    /// A machine tool's output into `file` (at most 60 s; best effort).
    pub(super) fn tool(&self, tool: &Path, args: &[&str], file: &str) -> anyhow::Result<()> {
        let mut child =
            Command::new(tool).args(args).stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn()?;
        let t0 = Instant::now();
        while child.try_wait()?.is_none() {
            if t0.elapsed() > Duration::from_secs(60) {
                let _ = child.kill();
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let o = child.wait_with_output()?;
        let mut text = o.stdout;
        text.extend_from_slice(&o.stderr);
        crate::fsx::write_atomic(&self.out.join(file), &text)
    }
}

pub(super) fn exit_text(s: std::process::ExitStatus) -> String {
    match s.code() {
        Some(c) => format!("exit {c}"),
        None => {
            use std::os::unix::process::ExitStatusExt;
            format!("signal {}", s.signal().unwrap_or(0))
        }
    }
}

/// A tool beside the binary (a bundle has `vulkaninfo` there) or on the PATH.
pub(super) fn find_tool(exe: &Path, name: &str) -> Option<PathBuf> {
    let beside = exe.parent().map(|d| d.join(name));
    if let Some(b) = beside.filter(|b| b.is_file()) {
        return Some(b);
    }
    std::env::var_os("PATH")?.to_str()?.split(':').map(|d| Path::new(d).join(name)).find(|p| p.is_file())
}
