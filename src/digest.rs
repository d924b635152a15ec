//! Digests of results, for proving that a change keeps every hit and counter bit for bit:
//! with `HALFTRACE_DIGESTS=FILE` set, every CPU reference traversal, every kernel dispatch
//! and every baseline run appends one line to FILE — what ran, the rays (count and a hash
//! of their bytes) and a hash of the hits and of the counters. Two runs of the same command
//! before and after a change give the same lines (sorted, duplicates removed) when nothing
//! changed. The hash is FNV-1a (64 bits) of the records' bytes, stable across platforms and
//! compiler versions.

use crate::base::Ray;
use crate::base::{Counters, Hit};
use std::io::Write;
use std::sync::Mutex;

/// The environment variable naming the digest file.
pub const VAR: &str = "HALFTRACE_DIGESTS";

/// FNV-1a, 64 bits.
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

static FILE: Mutex<()> = Mutex::new(());

/// Appends the digest line of one result when [`VAR`] is set: `kind`, `label` (what ran),
/// the rays, the hits and, when there are any, the counters.
pub fn record(kind: &str, label: &str, rays: &[Ray], hits: &[Hit], counters: Option<&[Counters]>) {
    let Some(path) = std::env::var_os(VAR) else { return };
    let c = counters.map(|c| format!("{:016x}", fnv1a(bytemuck::cast_slice(c)))).unwrap_or_else(|| "-".into());
    let line = format!(
        "{kind}\t{label}\trays={}:{:016x}\thits={:016x}\tcounters={c}\n",
        rays.len(),
        fnv1a(bytemuck::cast_slice(rays)),
        fnv1a(bytemuck::cast_slice(hits))
    );
    let _guard = FILE.lock();
    let written = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| f.write_all(line.as_bytes()));
    if let Err(e) = written {
        eprintln!("warning: {VAR}={}: {e}", path.to_string_lossy());
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn fnv1a_matches_the_reference_values() {
        assert_eq!(super::fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(super::fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(super::fnv1a(b"foobar"), 0x8594_4171_f739_67e8);
    }
}
