#!/usr/bin/env bash
# Regenerates docs/sample-report — the project's face — from one clean commit, in one go:
#   the default sweep on the bundled scene (lavapipe), the compiler's view of every default
#   AMD family and every other vendor's model on both compiler releases side by side (`isa
#   --compilers pinned,newest`: the drm-shim compilers of scripts/install-compilers.sh and the
#   newest Mesa of scripts/install-newest-compilers.sh), AMD's estimated cycles per ray on the
#   bundled scene, the memory side of a ray on every modelled GPU (each kernel's resident waves
#   from the pinned compilers' occupancy, as the estimate's), then `report` over the folder.
# The folder records the commit (SAMPLE-COMMIT) and a hash of the kernels' SPIR-V (spirv.sha256):
# CI fails when the kernels change and the sample report does not follow (.ci/run).
# Usage: bash scripts/sample-report.sh   (about 15 minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! git diff --quiet HEAD -- src glsl spirv scenes Cargo.toml Cargo.lock build.rs; then
  echo "sample-report: commit first — the sample names the commit it was made at" >&2
  exit 1
fi
cargo build --release
bin=$PWD/target/release/halftrace
tmp=$(mktemp -d)
out=$tmp/sample-report
$bin sweep --out "$out"
$bin isa --family "$(IFS=,; echo "polaris10,vega10,navi10,navi21,navi31,gfx1201"),vendors" --compilers pinned,newest \
  --out "$out" --force
$bin estimate --family vega10,navi21,navi31,gfx1201 --out "$out" --force
$bin memory --rays primary,ao --estimate "$out" --compilers pinned --out "$out" --force
git rev-parse HEAD > "$out/SAMPLE-COMMIT"
bash scripts/spirv-hash.sh > "$out/spirv.sha256"
rm -rf docs/sample-report
cp -r "$out" docs/sample-report
rm -rf "$tmp"
# Rendered in place, so the report names the folder it is read from.
$bin report docs/sample-report
echo "sample-report: docs/sample-report made at $(git rev-parse --short=12 HEAD)"
