#!/usr/bin/env bash
# Installs the newest Mesa's shader compilers beside the pinned build of install-compilers.sh,
# in seconds and without building or installing anything system-wide: Debian sid's binary
# packages (mesa-vulkan-drivers, mesa-drm-shim and what they depend on, glibc included), which
# this machine's Debian mirror serves, downloaded with a private apt state (its sources list,
# lists, cache and status in the cache folder — the system's own apt is not touched) and
# unpacked into ${HALFTRACE_CACHE:-${XDG_CACHE_HOME:-~/.cache}/halftrace}/compilers/debian-mesa-<version>/.
#
# The folder has root/ (the unpacked packages), lib/ (the drm-shims), icd/ (the drivers'
# manifests pointing into root/), patchelf (bookworm's, unpacked) and RELEASE. sid's glibc is
# newer than the host's, so halftrace runs each model's child process as a copy of itself whose
# interpreter and DT_RPATH point into root/ (isa::shim; `isa --compilers DIR` picks the folder).
# Idempotent: a complete folder for the newest version is left as it is. A mirror that no longer
# serves sid is said, with the mirror's name, and the script fails.
set -euo pipefail
cd "$(dirname "$0")/.."
cache=${HALFTRACE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/halftrace}/compilers
state=$cache/.debian-sid-apt
t0=$SECONDS
# The mirror the system's Debian sources use (never a host name written here).
mirror=$(grep -h -m1 -E '^URIs:' /etc/apt/sources.list.d/debian.sources 2>/dev/null | awk '{print $2}' || true)
if [ -z "$mirror" ]; then
  mirror=$(grep -h -m1 -E '^deb ' /etc/apt/sources.list 2>/dev/null | awk '{print $2}' || true)
fi
[ -n "$mirror" ] || { echo "install-newest-compilers: no Debian mirror found in /etc/apt" >&2; exit 1; }
mkdir -p "$state"/{lists/partial,cache/archives/partial,debs}
echo "deb [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] $mirror sid main" > "$state/sources.list"
touch "$state/status"
apt=(-o Dir::Etc::SourceList="$state/sources.list" -o Dir::Etc::SourceParts=/dev/null
  -o Dir::State::Lists="$state/lists" -o Dir::Cache="$state/cache" -o Dir::State::Status="$state/status"
  -o APT::Architecture=amd64 -o Debug::NoLocking=1 -o APT::Sandbox::User="$(id -un)")
if ! apt-get "${apt[@]}" -qq update 2>"$state/update.err"; then
  echo "install-newest-compilers: $mirror does not serve Debian sid's binary packages: $(tail -1 "$state/update.err")" >&2
  exit 1
fi
version=$(apt-cache "${apt[@]}" show --no-all-versions mesa-vulkan-drivers 2>/dev/null | awk '/^Version:/ {print $2; exit}')
[ -n "$version" ] || { echo "install-newest-compilers: $mirror's sid has no mesa-vulkan-drivers" >&2; exit 1; }
upstream=${version#*:}; upstream=${upstream%%-*}
dest=$cache/debian-mesa-$upstream
if [ -f "$dest/complete" ] && [ "$(cat "$dest/RELEASE")" = "$version" ]; then
  echo "install-newest-compilers: $dest is complete (Mesa $version from sid); nothing to do"
  exit 0
fi
rm -rf "$dest" "$state/debs"
mkdir -p "$dest"/{root,lib,icd} "$state/debs"
pkgs=$(apt-cache "${apt[@]}" depends --recurse --no-recommends --no-suggests --no-conflicts --no-breaks \
  --no-replaces --no-enhances mesa-vulkan-drivers mesa-drm-shim libvulkan1 | grep '^[a-z]' | sort -u)
(cd "$state/debs" && apt-get "${apt[@]}" -qq download $pkgs)
for d in "$state/debs"/*.deb; do dpkg-deb -x "$d" "$dest/root"; done
# patchelf from the host's own release, unpacked (not installed).
(cd "$state/debs" && apt-get -qq download patchelf && dpkg-deb -x patchelf_*.deb "$state/patchelf")
cp "$state/patchelf/usr/bin/patchelf" "$dest/patchelf"
libs=$dest/root/usr/lib/x86_64-linux-gnu
[ -x "$dest/root/usr/lib64/ld-linux-x86-64.so.2" ] || { echo "install-newest-compilers: no loader in sid's libc6" >&2; exit 1; }
# LLVM's RUNPATH is $ORIGIN/../lib: let that name the same folder.
ln -sfn x86_64-linux-gnu "$dest/root/usr/lib/lib"
for s in "$libs"/lib*_noop_drm_shim.so; do ln -sfn "$s" "$dest/lib/$(basename "$s")"; done
# Each driver's manifest, its bare library name made a path into root/, under the name
# halftrace's vendor files use for it.
icd() {
  local from=$1 to=$2 lib
  [ -f "$dest/root/usr/share/vulkan/icd.d/$from" ] || return 0
  lib=$(sed -n 's/.*"library_path": *"\([^"]*\)".*/\1/p' "$dest/root/usr/share/vulkan/icd.d/$from")
  sed "s#\"library_path\": *\"[^\"]*\"#\"library_path\": \"$libs/${lib##*/}\"#" \
    "$dest/root/usr/share/vulkan/icd.d/$from" > "$dest/icd/$to"
}
icd freedreno_icd.json freedreno.json
icd nouveau_icd.json nouveau.json
icd intel_icd.json intel.json
icd radeon_icd.json radeon.json
icd asahi_icd.json asahi.json
echo "$version" > "$dest/RELEASE"
touch "$dest/complete"
echo "install-newest-compilers: Mesa $version from sid into $dest ($(echo $pkgs | wc -w) packages," \
  "$(du -sh "$state/debs" | cut -f1) downloaded, $(du -sh "$dest" | cut -f1) unpacked) in $((SECONDS - t0)) s;" \
  "shims: $(ls "$dest/lib" | sed 's/^lib\(.*\)_noop_drm_shim.so$/\1/' | tr '\n' ' ')"
