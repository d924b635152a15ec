//! Where `isa` builds: AMD families (RADV null devices, probed: RADV aborts on a family it does
//! not know), other vendors' models under their drm-shims, devices by name — what `--family`
//! names resolved and checked once ([`families`]) for `isa` and `estimate` alike.

use super::shim;
use crate::gpu::null::{self, Family};
use std::path::{Path, PathBuf};

/// Where kernels are built.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    /// An AMD family: RADV's null device in this process, or — with a compilers folder that
    /// has the amdgpu shim (Mesa 26 on: [`shim::amd_shim`]) — under that shim in a child process.
    Family(String, Option<PathBuf>),
    /// Another vendor's model under its drm-shim in the compilers folder, built in a child
    /// process ([`shim`]).
    Model(String, PathBuf),
    /// A device by index or name (its driver must expose pipeline statistics).
    Device(String),
}

/// The families of [`null::FAMILIES`] the installed RADV opens a null device for — or, with a
/// compilers folder `amd` that has the amdgpu shim, those its shim fakes. RADV aborts the
/// process on a family it does not know, so each is tried in a child process: `exe
/// probe-family` (the halftrace binary, or the folder's copy of it) with `RADV_FORCE_FAMILY` or
/// `AMDGPU_GPU_ID` set, a few tens of milliseconds each, eight at a time.
pub fn known_families(exe: &Path, amd: Option<&Path>) -> anyhow::Result<Vec<Family>> {
    let under = match amd {
        Some(d) => {
            let s = shim::amd_shim(d).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: no amdgpu drm-shim or RADV manifest there (Mesa {})",
                    d.display(),
                    shim::release(d)
                )
            })?;
            Some((d, s, shim::child_exe(exe, d)?))
        }
        None => None,
    };
    let probe = |f: &Family| -> bool {
        let mut cmd = match &under {
            Some((dir, s, child)) => {
                let mut c = std::process::Command::new(child);
                c.envs(shim::family_environment(s, f.name, dir));
                c
            }
            None => {
                let mut c = std::process::Command::new(exe);
                c.env("RADV_FORCE_FAMILY", f.name);
                c
            }
        };
        cmd.arg("probe-family")
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
            let hs: Vec<_> = chunk.iter().map(|f| s.spawn(|| probe(f))).collect();
            for (h, flag) in hs.into_iter().zip(flags.iter_mut()) {
                *flag = h.join().unwrap_or(false);
            }
        });
    }
    Ok(null::FAMILIES.iter().zip(ok).filter(|(_, k)| *k).map(|(f, _)| *f).collect())
}

/// The AMD families and the other vendors' models `--family` names (`vendors`: every model;
/// `all`: every family the installed RADV opens and every model), each once in the order
/// asked, checked: an AMD family must be one the installed RADV opens — or, with a compilers
/// folder `amd` that has the amdgpu shim, one that shim opens (probed only when one is asked
/// for). `default`: nothing asked means the default
/// families. Returns (families, models, the models only a group — `vendors`, `all` — named:
/// those a compilers release lacks are left out rather than refused).
pub fn families(
    asked: &[String],
    exe: &Path,
    default: bool,
    amd: Option<&Path>,
) -> anyhow::Result<(Vec<String>, Vec<String>, Vec<String>)> {
    let asked: Vec<String> = asked.iter().map(|f| f.to_lowercase()).collect();
    let is_model = |f: &str| crate::vendor::find_model(f).is_some();
    let defaulted = asked.is_empty() && default;
    let amd_asked = defaulted || asked.iter().any(|f| f != "vendors" && !is_model(f));
    let known = if amd_asked { known_families(exe, amd)? } else { Vec::new() };
    // Who opens the families, for the messages.
    let opener = match amd.filter(|d| shim::amd_shim(d).is_some()) {
        Some(d) => format!("the amdgpu shim of Mesa {} opens", shim::release(d)),
        None => "the installed RADV opens".to_string(),
    };
    let names: Vec<&str> = known.iter().map(|f| f.name).collect();
    let every_model = || crate::vendor::models().map(|(_, m)| m.name.to_string());
    let mut families = if defaulted { default_families(&known) } else { Vec::new() };
    let (mut models, mut named) = (Vec::new(), Vec::new());
    for f in asked {
        match f.as_str() {
            "all" => {
                families.extend(names.iter().map(|n| n.to_string()));
                models.extend(every_model());
            }
            "vendors" => models.extend(every_model()),
            _ if is_model(&f) => {
                named.push(f.clone());
                models.push(f);
            }
            _ => families.push(f),
        }
    }
    // Each once, in the order asked.
    let once = |v: Vec<String>| -> Vec<String> {
        v.iter().enumerate().filter(|(i, f)| !v[..*i].contains(f)).map(|(_, f)| f.clone()).collect()
    };
    let (families, models) = (once(families), once(models));
    anyhow::ensure!(
        families.is_empty() || !names.is_empty(),
        "{}",
        match amd {
            Some(d) => format!(
                "the compilers in {} (Mesa {}) open no AMD family: RADV and the amdgpu shim are both needed there",
                d.display(),
                shim::release(d)
            ),
            None => "no RADV null device opens here (RADV, in Debian's mesa-vulkan-drivers, provides them for any AMD \
                     family); or name a device whose driver reports pipeline statistics with --device"
                .to_string(),
        }
    );
    for f in &families {
        let all_models: Vec<&str> = crate::vendor::models().map(|(_, m)| m.name).collect();
        anyhow::ensure!(
            names.contains(&f.as_str()),
            "--family '{f}': neither an AMD family {opener} ({}) nor a model of the other vendors ({})",
            names.join(", "),
            all_models.join(", ")
        );
    }
    let grouped = models.iter().filter(|m| !named.contains(m)).cloned().collect();
    Ok((families, models, grouped))
}

/// The families `isa` builds for by default: those of [`null::DEFAULT_FAMILIES`] in `known`.
pub fn default_families(known: &[Family]) -> Vec<String> {
    null::DEFAULT_FAMILIES.iter().filter(|n| known.iter().any(|k| k.name == **n)).map(|n| n.to_string()).collect()
}

/// The compilers releases `--compilers` names, each once in the order asked: `None` is the
/// pinned one (`pinned`, or nothing asked).
pub fn releases(asked: &[String]) -> anyhow::Result<Vec<Option<String>>> {
    let mut out: Vec<Option<String>> = Vec::new();
    // Each named folder resolved (`newest` and its folder by path are one release), with its
    // Mesa release: two folders of one release would give the same rows twice.
    let mut seen: Vec<(PathBuf, String, String)> = Vec::new();
    for c in asked {
        anyhow::ensure!(!c.trim().is_empty(), "--compilers: an empty name (pinned, newest or a compilers folder)");
        let r = (c != "pinned").then(|| c.clone());
        if out.contains(&r) {
            continue;
        }
        let dir = match &r {
            Some(c) => Some(shim::compilers_for(Some(c)).map_err(anyhow::Error::msg)?),
            None => shim::compilers().ok(),
        };
        if let Some(dir) = dir {
            let canon = dir.canonicalize().unwrap_or(dir.clone());
            let rel = shim::release(&dir);
            if let Some((_, _, first)) = seen.iter().find(|(p, _, _)| *p == canon) {
                eprintln!("note: --compilers {c} is the same folder as {first}: built once");
                continue;
            }
            if let Some((_, _, first)) = seen.iter().find(|(_, r2, _)| *r2 == rel) {
                anyhow::bail!("--compilers {c} and {first} are both Mesa {rel}: name one of them");
            }
            seen.push((canon, rel, c.clone()));
        }
        out.push(r);
    }
    if out.is_empty() {
        out.push(None);
    }
    Ok(out)
}

/// What `--family` names on one compilers release (`choice`: as `--compilers` names one —
/// `pinned` or `None` the pinned release, else `newest` or a folder; [`releases`]): the AMD families
/// — under the release's amdgpu shim where its folder has one, else RADV's null devices — and
/// the other vendors' models under the release's shims. A release named for nothing it can
/// build is refused. `one_of_several`: the release is one of several, so a model it lacks is
/// left out (said) rather than refused — [`releases_targets`] refuses one no release has.
pub fn release_targets(
    asked: &[String],
    exe: &Path,
    default: bool,
    choice: Option<&str>,
    one_of_several: bool,
) -> anyhow::Result<Vec<Target>> {
    let choice = choice.filter(|c| *c != "pinned");
    let folder = choice.map(|c| shim::compilers_for(Some(c)).map_err(anyhow::Error::msg)).transpose()?;
    let amd = folder.filter(|d| shim::amd_shim(d).is_some());
    let (families, models, grouped) = families(asked, exe, default, amd.as_deref())?;
    let grouped = if one_of_several { models.clone() } else { grouped };
    let (dir, models) = shim::models_compilers(models, &grouped, choice)?;
    if let Some(c) = choice {
        anyhow::ensure!(
            !models.is_empty() || (amd.is_some() && !families.is_empty()),
            "--compilers {c}: nothing asked for builds there: name a model of the other vendors{} (--family)",
            if amd.is_some() { " or an AMD family" } else { "" }
        );
    }
    let mut targets: Vec<Target> = families.into_iter().map(|f| Target::Family(f, amd.clone())).collect();
    if let Some(d) = dir {
        targets.extend(models.into_iter().map(|m| Target::Model(m, d.clone())));
    }
    Ok(targets)
}

/// [`release_targets`] of every release `--compilers` names ([`releases`]), in that order; a
/// model no release can build is refused, naming it.
pub fn releases_targets(
    asked: &[String],
    exe: &Path,
    default: bool,
    compilers: &[String],
) -> anyhow::Result<(Vec<Target>, usize)> {
    let releases = releases(compilers)?;
    let several = releases.len() > 1;
    let mut targets = Vec::new();
    for choice in &releases {
        targets.extend(release_targets(asked, exe, default, choice.as_deref(), several)?);
    }
    if several {
        for name in asked.iter().map(|f| f.to_lowercase()).filter(|f| crate::vendor::find_model(f).is_some()) {
            anyhow::ensure!(
                targets.iter().any(|t| matches!(t, Target::Model(m, _) if *m == name)),
                "--family {name}: none of the releases --compilers names ({}) has its drm-shim or driver",
                compilers.join(", ")
            );
        }
    }
    Ok((targets, releases.len()))
}
