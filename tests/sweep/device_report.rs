use super::*;
use std::os::unix::process::CommandExt;
use std::time::{Duration, Instant};

fn report_cmd(out: &Path, extra: &[&str]) -> Command {
    let scene = teapot();
    let mut c = Command::new(env!("CARGO_BIN_EXE_halftrace"));
    c.args(["device-report", "--scene", &scene, "--scenes-dir", "none", "--width", "16", "--height", "16", "--out"])
        .arg(out)
        .args(extra);
    c
}

fn state(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("device-report.json")).unwrap()).unwrap()
}

/// The report command on the default device: killed (with every step it started) once its
/// sweep has written a row, a new run into the folder refused, then resumed within a 1 s
/// budget: the finished steps are not run again, the sweep keeps its rows and adds some, and
/// the folder holds the device's report, which `report` reads as a sweep folder.
#[test]
fn device_report_is_interrupted_refused_and_resumed() {
    let out = tmp("device-report");
    let mut child = report_cmd(&out, &["--budget", "20m"])
        .process_group(0)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let pid = child.id();
    let t0 = Instant::now();
    loop {
        let rows = std::fs::read_to_string(out.join("sweep/results.csv")).map(|t| t.lines().count()).unwrap_or(0);
        if rows >= 2 {
            break;
        }
        assert!(child.try_wait().unwrap().is_none(), "the report ended before its sweep wrote a row");
        assert!(t0.elapsed() < Duration::from_secs(1200), "no sweep row within 20 minutes");
        std::thread::sleep(Duration::from_millis(200));
    }
    let killed = Command::new("kill").args(["-KILL", "--", &format!("-{pid}")]).status().unwrap();
    assert!(killed.success());
    let _ = child.wait();
    let s = state(&out);
    for step in ["devices", "conformance", "bench"] {
        assert_eq!(s["steps"][step]["done"], true, "{step} finished before the sweep: {s}");
    }
    assert!(s["steps"].get("sweep").is_none(), "the killed sweep is not recorded as finished: {s}");
    let before = read_rows(&out.join("sweep")).unwrap();
    assert!(!before.is_empty());
    let conf = out.join("conformance/conformance.csv");
    let conf_time = std::fs::metadata(&conf).unwrap().modified().unwrap();

    // A new report into the folder is refused, and changes nothing.
    let o = report_cmd(&out, &["--budget", "1s"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let names = err.contains("already holds") && err.contains("device-report.json");
    assert!(!o.status.success() && names && err.contains("--resume") && err.contains("--force"), "{err}");
    assert_eq!(state(&out), s);

    // Resumed with a 1 s budget: only the sweep runs (at least one more job).
    let o = report_cmd(&out, &["--budget", "1s", "--resume"]).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(!stderr.contains("conformance --quick") && !stderr.contains("bench (short)"), "{stderr}");
    assert_eq!(std::fs::metadata(&conf).unwrap().modified().unwrap(), conf_time, "conformance ran again");
    let after = read_rows(&out.join("sweep")).unwrap();
    assert!(after.len() > before.len(), "{} rows before, {} after", before.len(), after.len());
    for r in &before {
        let kept = after.iter().find(|a| a.id() == r.id()).unwrap_or_else(|| panic!("{} lost", r.kernel));
        assert_eq!(kept.mrays_median, r.mrays_median, "{} was measured again", r.kernel);
    }
    let s = state(&out);
    assert_eq!(s["runs"].as_array().unwrap().len(), 2);
    let sweep = s["steps"]["sweep"]["status"].as_str().unwrap();
    assert!(sweep.starts_with("partial: ") && sweep.contains(&format!("{} of ", after.len())), "{sweep}");
    assert!(s["steps"]["conformance"]["status"].as_str().unwrap().contains(" 0 failed"), "{s}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let (device, driver) = (s["device"].as_str().unwrap(), s["driver"].as_str().unwrap());
    assert!(md.starts_with(&format!("# halftrace device report: {device}")), "{md}");
    assert!(md.contains(driver) && md.contains("| conformance | ok (") && md.contains("## Bench"), "{md}");
    for f in ["devices.txt", "bench.md", "conformance/conformance.md", "sweep/report.md", "logs/sweep.log"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(std::fs::read_to_string(out.join("devices.txt")).unwrap().contains(device));

    // `report` reads the device's folder as its sweep.
    let merged = tmp("device-report-merged");
    let o = Command::new(env!("CARGO_BIN_EXE_halftrace"))
        .arg("report")
        .arg(&out)
        .arg("--out")
        .arg(&merged)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(read_rows(&merged).unwrap().len(), after.len());
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&merged);
}

/// Writes `out`'s device-report.json as a report of the default device (the teapot at 16 × 16)
/// whose `steps` finished with those statuses; returns the device.
fn record_finished(out: &Path, steps: &[(&str, &str)]) -> halftrace::gpu::DeviceInfo {
    use halftrace::devreport::{choose_device, State, StepRecord};
    let dev = choose_device(None).unwrap();
    let done = |status: &str| StepRecord { status: status.into(), seconds: 1.0, done: true, output: String::new() };
    let record = State {
        device: dev.name.clone(),
        driver: dev.driver.clone(),
        scenes: vec![teapot()],
        width: 16,
        height: 16,
        steps: steps.iter().map(|(k, v)| (k.to_string(), done(v))).collect(),
        ..Default::default()
    };
    std::fs::write(out.join("device-report.json"), serde_json::to_string(&record).unwrap()).unwrap();
    dev
}

/// `--resume` does not trust device-report.json alone: a step recorded as finished whose file
/// was deleted since runs again; the steps whose files are there do not.
#[test]
fn resume_reruns_a_finished_step_whose_file_is_gone() {
    let out = tmp("device-report-gone");
    // A finished report, as far as its record goes: a real one-job sweep, stand-ins for the
    // other steps' files.
    let o = sweep(
        &out.join("sweep"),
        &["--rays", "primary", "--layouts", "f32", "--branchings", "4", "--packets", "1", "--layout-branchings", "4"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = halftrace::report::merge::merge(&[out.join("sweep")], None).unwrap();
    assert!(md.report.is_file());
    std::fs::create_dir_all(out.join("conformance")).unwrap();
    for (f, text) in
        [("conformance/conformance.md", "earlier"), ("conformance/conformance.csv", "earlier"), ("bench.md", "earlier")]
    {
        std::fs::write(out.join(f), text).unwrap();
    }
    let dev = record_finished(
        &out,
        &[
            ("devices", "ok"),
            ("conformance", "ok"),
            ("bench", "ok"),
            ("sweep", "ok: 1 jobs"),
            ("isa", "skipped: not asked"),
        ],
    );
    // devices.txt is not there (deleted, say): devices runs again, nothing else does.
    let o = report_cmd(&out, &["--budget", "60s", "--resume"]).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("devices is recorded as finished but devices.txt is missing"), "{stderr}");
    assert!(std::fs::read_to_string(out.join("devices.txt")).unwrap().contains(&dev.name));
    assert!(out.join("logs/devices.log").is_file());
    for step in ["conformance", "bench", "sweep"] {
        assert!(!out.join(format!("logs/{step}.log")).exists(), "{step} ran again: {stderr}");
    }
    assert_eq!(std::fs::read_to_string(out.join("bench.md")).unwrap(), "earlier");
    assert_eq!(std::fs::read_to_string(out.join("conformance/conformance.md")).unwrap(), "earlier");
    let s = state(&out);
    assert_eq!(s["steps"]["devices"]["status"], "ok");
    assert_eq!(s["steps"]["devices"]["output"], "devices.txt");
    assert!(s["steps"]["devices"]["seconds"].as_f64().unwrap() != 1.0, "{s}");
    assert_eq!(s["runs"].as_array().unwrap().len(), 1);
    let _ = std::fs::remove_dir_all(&out);
}

/// The child processes of `pid` whose command line holds `word`.
fn children_running(pid: u32, word: &str) -> Vec<u32> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(p) = e.file_name().to_string_lossy().parse::<u32>() else { continue };
        let stat = std::fs::read_to_string(format!("/proc/{p}/stat")).unwrap_or_default();
        let ppid = stat.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(1)?.parse::<u32>().ok());
        let cmd = std::fs::read(format!("/proc/{p}/cmdline")).unwrap_or_default();
        if ppid == Some(pid) && String::from_utf8_lossy(&cmd).split('\0').any(|a| a == word) {
            found.push(p);
        }
    }
    found
}

/// A step whose child dies (killed here, as a driver crash or the OOM killer would) stays
/// failed, naming its log — not "partial … budget reached" — and the report exits non-zero.
#[test]
fn a_killed_step_is_failed_not_partial() {
    let out = tmp("device-report-killed");
    std::fs::create_dir_all(out.join("conformance")).unwrap();
    for f in ["devices.txt", "conformance/conformance.md", "conformance/conformance.csv", "bench.md"] {
        std::fs::write(out.join(f), "earlier").unwrap();
    }
    record_finished(&out, &[("devices", "ok"), ("conformance", "ok"), ("bench", "ok"), ("isa", "ok")]);
    let mut child = report_cmd(&out, &["--budget", "20m", "--resume"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let sweep = loop {
        if let Some(&p) = children_running(child.id(), "sweep").first() {
            break p;
        }
        assert!(child.try_wait().unwrap().is_none(), "the report ended before its sweep started");
        assert!(t0.elapsed() < Duration::from_secs(300), "no sweep child within 5 minutes");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(Command::new("kill").args(["-KILL", &sweep.to_string()]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(!o.status.success(), "a failed step ends the report with an error:\n{stdout}\n{stderr}");
    assert!(stderr.contains("step(s) failed: sweep") && stderr.contains("logs"), "{stderr}");
    let s = state(&out);
    let st = s["steps"]["sweep"]["status"].as_str().unwrap();
    assert!(st.starts_with("failed (signal 9; see logs/sweep.log)") && !st.contains("partial"), "{st}");
    assert_eq!(s["steps"]["sweep"]["done"], false, "a failed sweep runs again on --resume: {s}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("failed (signal 9"), "{md}");
    let _ = std::fs::remove_dir_all(&out);
}
