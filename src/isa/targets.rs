//! Where `isa` builds: AMD families (RADV null devices, probed: RADV aborts on a family it does
//! not know), other vendors' models under their drm-shims, devices by name — what `--family`
//! names resolved and checked once ([`families`]) for `isa` and `estimate` alike.

use crate::gpu::null::{self, Family};
use std::path::Path;

/// Where kernels are built.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Target {
    /// RADV's null device of a family.
    Family(String),
    /// Another vendor's model under its drm-shim, built in a child process ([`shim`]).
    Model(String),
    /// A device by index or name (its driver must expose pipeline statistics).
    Device(String),
}

/// The families of [`null::FAMILIES`] the installed RADV opens a null device for. RADV
/// aborts the process on a family it does not know, so each is tried in a child process:
/// `exe probe-family` (the halftrace binary) with `RADV_FORCE_FAMILY` set, a few tens of
/// milliseconds each, eight at a time.
pub fn known_families(exe: &Path) -> Vec<Family> {
    let probe = |f: &Family| -> bool {
        std::process::Command::new(exe)
            .arg("probe-family")
            .env("RADV_FORCE_FAMILY", f.name)
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
            let hs: Vec<_> = chunk.iter().map(|f| s.spawn(move || probe(f))).collect();
            for (h, flag) in hs.into_iter().zip(flags.iter_mut()) {
                *flag = h.join().unwrap_or(false);
            }
        });
    }
    null::FAMILIES.iter().zip(ok).filter(|(_, k)| *k).map(|(f, _)| *f).collect()
}

/// The AMD families and the other vendors' models `--family` names (`vendors`: every model;
/// `all`: every family the installed RADV opens and every model), each once in the order
/// asked, checked: an AMD family must be one the installed RADV opens (probed only when one is
/// asked for). `default`: nothing asked means the default
/// families. Returns (families, models, the models only a group — `vendors`, `all` — named:
/// those a compilers release lacks are left out rather than refused).
pub fn families(
    asked: &[String],
    exe: &Path,
    default: bool,
) -> anyhow::Result<(Vec<String>, Vec<String>, Vec<String>)> {
    let asked: Vec<String> = asked.iter().map(|f| f.to_lowercase()).collect();
    let is_model = |f: &str| crate::vendor::find_model(f).is_some();
    let defaulted = asked.is_empty() && default;
    let amd_asked = defaulted || asked.iter().any(|f| f != "vendors" && !is_model(f));
    let known = if amd_asked { known_families(exe) } else { Vec::new() };
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
        "no RADV null device opens here (RADV, in Debian's mesa-vulkan-drivers, provides them for any AMD family); \
         or name a device whose driver reports pipeline statistics with --device"
    );
    for f in &families {
        let all_models: Vec<&str> = crate::vendor::models().map(|(_, m)| m.name).collect();
        anyhow::ensure!(
            names.contains(&f.as_str()),
            "--family '{f}': neither an AMD family the installed RADV opens ({}) nor a model of the other vendors ({})",
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
