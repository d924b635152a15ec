//! Every vendor's production compiler without the GPU: Mesa's Vulkan drivers for Qualcomm
//! Adreno (turnip), Arm Mali (panvk), Intel (anv), NVIDIA (NVK) and Broadcom VideoCore (v3dv),
//! each opened under its drm-shim — a preloaded library that fakes the kernel driver, so the
//! driver builds pipelines and reports their statistics while nothing runs. The shims and the
//! drivers Debian does not ship are built by `scripts/install-compilers.sh` into a cache
//! ([`compilers`]).
//!
//! The vendors and their models are in `crate::vendor`. One driver and one model per process
//! (the shim's model comes from the environment when the driver opens): each model is built in a child process (`halftrace isa-model`) that
//! prints one row per kernel as it goes, so that the rows a driver wrote before crashing (v3dv
//! has crashed at teardown) survive, and the crash is reported by model.

use crate::base::Status;
use crate::report::isa::IsaRow;
use crate::variant::KernelSpec;
use crate::vendor::{Model, Shim, Vendor};
use anyhow::Context as _;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};

/// Where `scripts/install-compilers.sh` put the drivers and shims: `HALFTRACE_COMPILERS`, else
/// the newest complete `mesa-*` folder under `${HALFTRACE_CACHE:-${XDG_CACHE_HOME:-~/.cache}/
/// halftrace}/compilers`. The error says how to install them.
pub fn compilers() -> Result<PathBuf, String> {
    if let Some(d) = std::env::var_os("HALFTRACE_COMPILERS").map(PathBuf::from) {
        return if complete(&d) {
            Ok(d)
        } else {
            Err(format!(
                "HALFTRACE_COMPILERS={}: not a complete compilers folder (scripts/install-compilers.sh makes one)",
                d.display()
            ))
        };
    }
    let dir = cache_dir().map(|c| c.join("compilers"));
    newest_complete(dir.as_deref(), "mesa-").ok_or_else(|| {
        format!(
            "the other vendors' compilers are not installed{}: run `bash scripts/install-compilers.sh` (about 20 \
             minutes, once; AMD's families need nothing)",
            dir.map(|d| format!(" (nothing complete in {})", d.display())).unwrap_or_default()
        )
    })
}

/// The compilers folder `isa --compilers` names: `newest`, the newest complete
/// `debian-mesa-*` folder (`scripts/install-newest-compilers.sh`: Debian sid's binaries), or a
/// folder of either script; without one, the pinned build ([`compilers`]).
pub fn compilers_for(choice: Option<&str>) -> Result<PathBuf, String> {
    match choice {
        None => compilers(),
        Some("newest") => {
            let dir = cache_dir().map(|c| c.join("compilers"));
            newest_complete(dir.as_deref(), "debian-mesa-").ok_or_else(|| {
                format!(
                    "--compilers newest: no newest Mesa installed{}: run `bash scripts/install-newest-compilers.sh` \
                         (seconds)",
                    dir.map(|d| format!(" (no complete debian-mesa-* folder in {})", d.display())).unwrap_or_default()
                )
            })
        }
        Some(d) if complete(Path::new(d)) => Ok(PathBuf::from(d)),
        Some(d) => Err(format!(
            "--compilers {d}: not a complete compilers folder (scripts/install-compilers.sh and \
             scripts/install-newest-compilers.sh make them), nor `newest`"
        )),
    }
}

/// Whether `d` is a complete compilers folder (its script finished: `complete`, `lib/`, `icd/`).
fn complete(d: &Path) -> bool {
    d.join("complete").is_file() && d.join("lib").is_dir() && d.join("icd").is_dir()
}

/// The complete compilers folder in `dir` whose name starts with `prefix` and that was
/// finished last.
fn newest_complete(dir: Option<&Path>, prefix: &str) -> Option<PathBuf> {
    std::fs::read_dir(dir?)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with(prefix)) && complete(p))
        .max_by_key(|p| p.join("complete").metadata().and_then(|m| m.modified()).ok())
}

/// halftrace's cache folder: `HALFTRACE_CACHE`, else `${XDG_CACHE_HOME:-~/.cache}/halftrace`.
pub fn cache_dir() -> Option<PathBuf> {
    std::env::var_os("HALFTRACE_CACHE").map(PathBuf::from).or_else(|| {
        std::env::var_os("XDG_CACHE_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
            .map(|c| c.join("halftrace"))
    })
}

/// The Mesa release of a compilers folder: its `RELEASE` file, else the version in its name.
pub fn release(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("RELEASE")).map(|t| t.trim().to_string()).unwrap_or_else(|_| {
        let n = dir.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
        n.trim_start_matches("debian-").trim_start_matches("mesa-").split('-').next().unwrap_or("").to_string()
    })
}

/// Whether the folder has the shim of `vendor`'s models: an error naming the models it cannot
/// build otherwise (sid's amd64 packages have no panfrost, v3d or intel shim).
pub fn check_models(dir: &Path, models: &[String]) -> Result<(), String> {
    let missing: Vec<String> = models
        .iter()
        .filter_map(|name| {
            let (v, m) = crate::vendor::find_model(name)?;
            let shim = v.shim?;
            (!dir.join("lib").join(shim.library()).is_file() || !dir.join("icd").join(shim.icd).is_file())
                .then(|| format!("{} ({})", m.name, shim.driver))
        })
        .collect();
    if missing.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "the compilers in {} (Mesa {}) have no drm-shim or driver for {}; leave them out, or use another \
             --compilers",
            dir.display(),
            release(dir),
            missing.join(", ")
        ))
    }
}

/// The compilers folder for `models` (`None` without models: the caller refuses a `--compilers`
/// that nothing uses): [`compilers_for`] `choice`,
/// checked before any work to have each model's shim and driver ([`check_models`]) — but for
/// the models only a group named (`grouped`: `vendors`, `all`), which are left out, said on
/// stderr, where the release has no shim for them. Returns the folder and the models to build.
pub fn models_compilers(
    models: Vec<String>,
    grouped: &[String],
    choice: Option<&str>,
) -> anyhow::Result<(Option<PathBuf>, Vec<String>)> {
    if models.is_empty() {
        return Ok((None, models));
    }
    let dir = compilers_for(choice).map_err(anyhow::Error::msg)?;
    let (kept, left): (Vec<String>, Vec<String>) =
        models.into_iter().partition(|m| !grouped.contains(m) || check_models(&dir, std::slice::from_ref(m)).is_ok());
    if !left.is_empty() {
        eprintln!(
            "note: the compilers in {} (Mesa {}) have no drm-shim or driver for {}: left out",
            dir.display(),
            release(&dir),
            left.join(", ")
        );
    }
    check_models(&dir, &kept).map_err(anyhow::Error::msg)?;
    Ok((Some(dir), kept))
}

/// The binary a model's child runs: this one, or — where the folder carries its own C library
/// (`root/`, Debian sid's, newer than the host's) — a copy of it whose interpreter and DT_RPATH
/// point into the folder (made once per binary with the folder's `patchelf`; DT_RPATH, not
/// RUNPATH, so that the drivers' own dependencies resolve there too).
pub fn child_exe(exe: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    let root = dir.join("root");
    if !root.is_dir() {
        return Ok(exe.to_path_buf());
    }
    let meta = std::fs::metadata(exe).with_context(|| format!("reading {}", exe.display()))?;
    let stamp = meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).unwrap_or_default();
    let name = format!("halftrace-{:x}-{:x}", meta.len(), stamp.as_nanos());
    let bin = dir.join("bin");
    let dest = bin.join(&name);
    // Models run in parallel threads: one makes the copy, the others wait for it.
    static MAKING: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = MAKING.lock().unwrap_or_else(|e| e.into_inner());
    if dest.is_file() {
        return Ok(dest);
    }
    std::fs::create_dir_all(&bin).with_context(|| format!("creating {}", bin.display()))?;
    let tmp = bin.join(format!(".{name}.{}", std::process::id()));
    std::fs::copy(exe, &tmp).with_context(|| format!("copying {} to {}", exe.display(), tmp.display()))?;
    let libs = root.join("usr/lib/x86_64-linux-gnu");
    let out = Command::new(dir.join("patchelf"))
        .arg("--set-interpreter")
        .arg(root.join("usr/lib64/ld-linux-x86-64.so.2"))
        .arg("--force-rpath")
        .arg("--set-rpath")
        .arg(&libs)
        .arg(&tmp)
        .output()
        .with_context(|| format!("running {}", dir.join("patchelf").display()))?;
    if !out.status.success() {
        let _ = std::fs::remove_file(&tmp);
        anyhow::bail!("patchelf on a copy of {}: {}", exe.display(), String::from_utf8_lossy(&out.stderr).trim());
    }
    std::fs::rename(&tmp, &dest).with_context(|| format!("moving {} into place", dest.display()))?;
    Ok(dest)
}

/// The environment that opens a model's driver under its shim `s` of `dir`: the shim, the
/// driver's manifest, the model's own variables `model` (its `Model::env`), and the compiler's
/// summary where the vendor needs it.
pub fn environment(s: &Shim, model: &[(&str, &str)], dir: &Path) -> Vec<(String, String)> {
    let icd = dir.join("icd").join(s.icd).display().to_string();
    let mut env = vec![
        ("LD_PRELOAD".to_string(), dir.join("lib").join(s.library()).display().to_string()),
        ("VK_ICD_FILENAMES".to_string(), icd.clone()),
        // The loader's newer spelling would win over VK_ICD_FILENAMES.
        ("VK_DRIVER_FILES".to_string(), icd),
    ];
    env.extend(model.iter().map(|(k, v)| (k.to_string(), v.to_string())));
    // The compiler's own one-line summary per shader on stderr, where the vendor needs it.
    env.extend(s.summary_env.iter().map(|(k, v)| (k.to_string(), v.to_string())));
    env
}

/// AMD's shim in the compilers folder `dir`, where it has it and RADV's manifest (Mesa 26 on,
/// which has no null device: Debian's newest carries both; the pinned build neither).
pub fn amd_shim(dir: &Path) -> Option<Shim> {
    let s = crate::vendor::amd::AMD.shim?;
    (dir.join("lib").join(s.library()).is_file() && dir.join("icd").join(s.icd).is_file()).then_some(s)
}

/// AMD family `family` as the amdgpu shim's model (its environment: [`family_environment`]);
/// `None` for a name Mesa does not know.
pub fn family_model(family: &str) -> Option<Model> {
    let f = crate::gpu::null::family(family)?;
    Some(Model { name: f.name, display: f.name, generation: f.generation, env: &[] })
}

/// The environment that opens AMD family `family` under the amdgpu shim `s` of `dir`:
/// `AMDGPU_GPU_ID` names the family (the shim knows fewer than Mesa: an unknown one opens no
/// device).
pub fn family_environment(s: &Shim, family: &str, dir: &Path) -> Vec<(String, String)> {
    environment(s, &[("AMDGPU_GPU_ID", family)], dir)
}

/// The marker a child prints on stderr before building each kernel, so that the driver's
/// own printout after it (Mali's shaderdb line) is known to be that kernel's.
pub const MARKER: &str = "halftrace-isa-kernel ";

/// What one model's child process gave: its rows (one per build asked for) and, where the
/// driver crashed or the child failed, a note naming the model.
pub struct ModelRun {
    pub rows: Vec<IsaRow>,
    pub note: Option<String>,
}

/// Runs `cmd` with an empty stdin to its end, reading its stdout and, on a thread beside (so
/// that neither pipe fills while the other is read), its stderr: (stdout, exit status,
/// stderr, lossily decoded).
pub fn run_child(cmd: &mut Command) -> std::io::Result<(String, ExitStatus, String)> {
    let mut child = cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn()?;
    let mut err = child.stderr.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = err.read_to_end(&mut s);
        String::from_utf8_lossy(&s).to_string()
    });
    let mut stdout = String::new();
    child.stdout.take().expect("piped").read_to_string(&mut stdout)?;
    let status = child.wait()?;
    Ok((stdout, status, reader.join().unwrap_or_default()))
}

/// Builds `builds` on `vendor`'s model `m` in a child process `exe isa-model` with the shim's
/// environment. Rows the child printed before dying are kept; builds it never reported become
/// failed rows naming the crash. `args`: the child's command line ([`crate::isa::ModelArgs`]).
pub fn run_model(
    exe: &Path,
    (vendor, m): (&'static Vendor, &Model),
    dir: &Path,
    args: &crate::argv::Argv,
    builds: &[KernelSpec],
) -> anyhow::Result<ModelRun> {
    let shim = vendor.shim.ok_or_else(|| anyhow::anyhow!("{}: {} has no drm-shim", m.name, vendor.name))?;
    // An AMD family is the amdgpu shim's model by its environment.
    let env =
        if vendor.models.is_empty() { family_environment(&shim, m.name, dir) } else { environment(&shim, m.env, dir) };
    let exe = child_exe(exe, dir)?;
    let (stdout, status, stderr) = run_child(Command::new(&exe).args(&args.0).envs(env))?;
    let mut rows: Vec<IsaRow> = Vec::new();
    let mut bad_lines = 0;
    let mut other = String::new();
    for line in stdout.lines() {
        match serde_json::from_str::<IsaRow>(line) {
            Ok(r) => rows.push(IsaRow::typed(r)),
            Err(_) => {
                bad_lines += 1;
                other += line;
                other.push('\n');
            }
        }
    }
    // The driver's own printout (IR3_SHADER_DEBUG, INTEL_DEBUG, NAK_DEBUG, …) kept for
    // checking the statistics against: HALFTRACE_DRIVER_STDERR=DIR writes DIR/<model>.txt, and
    // what a driver prints on stdout instead (AGX_MESA_DEBUG=shaders) DIR/<model>.stdout.txt.
    if let Some(d) = std::env::var_os("HALFTRACE_DRIVER_STDERR").map(std::path::PathBuf::from) {
        let p = d.join(format!("{}.txt", m.name));
        std::fs::create_dir_all(&d)
            .and_then(|_| std::fs::write(&p, &stderr))
            .with_context(|| format!("HALFTRACE_DRIVER_STDERR: writing {}", p.display()))?;
        let p = d.join(format!("{}.stdout.txt", m.name));
        if !other.is_empty() {
            std::fs::write(&p, &other).with_context(|| format!("HALFTRACE_DRIVER_STDERR: writing {}", p.display()))?;
        } else if p.is_file() {
            // An earlier run's, which would be taken for this one's.
            std::fs::remove_file(&p).with_context(|| format!("HALFTRACE_DRIVER_STDERR: removing {}", p.display()))?;
        }
    }
    attach_estimates(&mut rows, &stderr);
    let mut note = None;
    if !status.success() {
        use std::os::unix::process::ExitStatusExt;
        let how = match status.signal() {
            Some(s) => format!("was killed by signal {s}"),
            None => format!("exited with status {}", status.code().unwrap_or(-1)),
        };
        let last = stderr.lines().rev().find(|l| l.starts_with("error:")).unwrap_or("").trim().to_string();
        let done = rows.len();
        note = Some(if done >= builds.len() {
            format!(
                "{} ({}): the driver's process {how} after writing all {done} rows (at teardown)",
                m.name, m.display
            )
        } else {
            format!(
                "{} ({}): the driver's process {how} after {done} of {} rows{}",
                m.name,
                m.display,
                builds.len(),
                if last.is_empty() { String::new() } else { format!(" ({last})") }
            )
        });
    }
    if bad_lines > 0 && note.is_none() {
        note = Some(format!("{}: {bad_lines} line(s) of its output were not rows", m.name));
    }
    // Builds the child never reported: failed, naming what happened to the process.
    if rows.len() < builds.len() {
        let why = note.clone().unwrap_or_else(|| format!("{}: no row came back", m.name));
        let template = rows.first().cloned().unwrap_or_else(|| IsaRow {
            device: m.display.to_string(),
            family: m.name.to_string(),
            generation: m.generation.to_string(),
            vendor: crate::vendor::VendorId(Some(vendor)),
            driver: shim.driver.to_string(),
            ..IsaRow::default()
        });
        for b in &builds[rows.len()..] {
            let v = b.variant;
            let id = crate::variant::KernelId::new(v, b.imp.unwrap_or(crate::variant::PacketImpl::Single), false);
            rows.push(IsaRow {
                kernel: id.name(),
                what: crate::report::What::Builtin(id),
                layout: v.layout.name().into(),
                math: v.math.name().into(),
                branching: v.branching,
                packet: v.packet,
                status: Status::Failed(format!("not built: {why}")),
                stats: Default::default(),
                asm: None,
                vs_f32: None,
                ..template.clone()
            });
        }
    }
    Ok(ModelRun { rows, note })
}

/// Each kernel's compiler summary (`BIFROST_MESA_DEBUG=shaderdb`, `V3D_DEBUG=shaderdb`): the
/// first `SHADER-DB` line after the kernel's marker (a driver's own internal shaders print
/// theirs when the device opens, before any marker), read into the row's statistics under
/// the names `shaderdb: <field>` and from there into its vendor-neutral columns.
pub fn attach_estimates(rows: &mut [IsaRow], stderr: &str) {
    let mut current: Option<String> = None;
    for line in stderr.lines() {
        if let Some(k) = line.strip_prefix(MARKER) {
            current = Some(k.trim().to_string());
        } else if let (Some(k), Some(db)) = (&current, shaderdb(line)) {
            if let Some(r) = rows.iter_mut().find(|r| &r.kernel == k && r.status.is_ok()) {
                r.stats.extend(db.into_iter().map(|(n, v)| (format!("shaderdb: {n}"), v)));
                r.fill_known();
            }
            current = None;
        }
    }
}

/// The fields of one `SHADER-DB… shader: 3310 inst, 334.000000 cycles, 1.1 fma, …, 48:233
/// spills:fills` line (Mali's estimate; V3D's `…, 64 max-temps, 136:217 spills:fills, …`), by
/// name.
pub fn shaderdb(line: &str) -> Option<Vec<(String, f64)>> {
    let (_, rest) = line.split_once("SHADER-DB")?;
    let (_, fields) = rest.split_once("shader:")?;
    let mut out = Vec::new();
    for f in fields.split(',') {
        let mut it = f.split_whitespace();
        let (Some(v), Some(name)) = (it.next(), it.next()) else { continue };
        if let Some((a, b)) = v.split_once(':') {
            let names: Vec<&str> = name.split(':').collect();
            if let ([na, nb], (Ok(x), Ok(y))) = (&names[..], (a.parse::<f64>(), b.parse::<f64>())) {
                out.push((na.to_string(), x));
                out.push((nb.to_string(), y));
            }
        } else if let Ok(x) = v.parse::<f64>() {
            out.push((name.to_string(), x));
        }
    }
    (!out.is_empty()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_shaderdb_line() {
        let l = "SHADER-DB: MESA_SHADER_COMPUTE shader: 5376 inst, 727.000000 cycles, 3.328125 fma, 54.187500 cvt, \
                 60.500000 sfu, 0.000000 v, 0.000000 t, 727.000000 ls, 2696 quadwords, 1 threads, 43 loops, \
                 150:503 spills:fills";
        let f = shaderdb(l).unwrap();
        let get = |n: &str| f.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
        assert_eq!(get("inst"), Some(5376.0));
        assert_eq!(get("cycles"), Some(727.0));
        assert_eq!(get("cvt"), Some(54.1875));
        assert_eq!(get("threads"), Some(1.0));
        assert_eq!((get("spills"), get("fills")), (Some(150.0), Some(503.0)));
        assert!(shaderdb("Unknown DRM_IOCTL_MSM_GET_PARAM 18").is_none());
        let v3d = "SHADER-DB-0000 - MESA_SHADER_COMPUTE shader: 4789 inst, 2 threads, 18 loops, 1742 uniforms, 64 \
                   max-temps, 136:217 spills:fills, 0 sfu-stalls, 4789 inst-and-stalls, 415 nops";
        let f = shaderdb(v3d).unwrap();
        let get = |n: &str| f.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
        assert_eq!((get("inst"), get("threads"), get("max-temps")), (Some(4789.0), Some(2.0), Some(64.0)));
        assert_eq!((get("spills"), get("fills")), (Some(136.0), Some(217.0)));
    }

    #[test]
    fn no_model_is_also_an_amd_family() {
        for (_, m) in crate::vendor::models() {
            assert!(crate::gpu::null::family(m.name).is_none(), "{} is also an AMD family", m.name);
        }
    }
}
