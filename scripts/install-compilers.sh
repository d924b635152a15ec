#!/usr/bin/env bash
# Installs the production shader compilers of GPUs this machine does not have, for
# `halftrace isa --family <model>`: Mesa's Vulkan drivers for Qualcomm Adreno (turnip), Arm Mali
# (panvk), NVIDIA (NVK) and Broadcom VideoCore (v3dv), each with its drm-shim (a preloaded
# library that fakes the kernel driver, so pipelines build and report their statistics while
# nothing runs), plus the drm-shim of Intel's anv, whose driver Debian already installs. AMD's
# compiler needs none of this: RADV's null device is in mesa-vulkan-drivers.
#
# Built from Debian's source of the installed Mesa (the release of our lavapipe and RADV, so
# every vendor's compiler is one Mesa), only the targets needed, into a cache outside the
# repository: ${HALFTRACE_CACHE:-${XDG_CACHE_HOME:-~/.cache}/halftrace}/compilers/mesa-<version>-<key>,
# where <key> changes with this script and its patches (scripts/mesa/: the v3d shim answers as a
# Raspberry Pi 4 or 5 kernel does). A second run with that folder complete does nothing.
# `halftrace` finds it there (or where HALFTRACE_COMPILERS points). Idempotent; about 20 minutes
# on 2 cores the first time (see docs/vendors.md).
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
# A python3 without mako (pyenv's, say) breaks Mesa's build: the system one first.
export PATH=/usr/bin:/bin:$PATH

cache=${HALFTRACE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/halftrace}/compilers
version=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
[ -n "$version" ] || { echo "install-compilers: mesa-vulkan-drivers is not installed (run scripts/install-deps.sh first)" >&2; exit 1; }
upstream=${version#*:}; upstream=${upstream%%-*}
key=$(cat "$0" scripts/mesa/*.patch | sha256sum | cut -c1-12)
dest=$cache/mesa-$upstream-$key
if [ -f "$dest/complete" ]; then
  echo "install-compilers: $dest is complete (Mesa $version); nothing to do"
  exit 0
fi
t0=$SECONDS

# Build dependencies. meson >= 1.4 and libdrm >= 2.4.121 come from bookworm-backports (which
# install-deps.sh enables); LLVM 15 and libclc only let meson configure the Intel tree (the
# shim is built, anv is not).
pkgs=(ninja-build pkg-config gcc g++ glslang-tools spirv-tools python3-mako python3-ply python3-yaml bison flex
  libzstd-dev libelf-dev libexpat1-dev zlib1g-dev libvulkan-dev llvm-15-dev libclang-15-dev libclang-cpp15-dev
  libclc-15-dev libclc-15 libllvmspirvlib-15-dev dpkg-dev xz-utils)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
. /etc/os-release
need_bpo=0
mv=$(meson --version 2>/dev/null || echo 0)
dpkg --compare-versions "$mv" ge 1.4 || need_bpo=1
dv=$(dpkg-query -W -f='${Version}' libdrm-dev 2>/dev/null || echo 0)
dpkg --compare-versions "$dv" ge 2.4.121 || need_bpo=1
if [ ${#missing[@]} -gt 0 ] || [ $need_bpo = 1 ]; then
  $SUDO apt-get update -qq
  [ ${#missing[@]} -eq 0 ] || DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
  if [ $need_bpo = 1 ]; then
    if [ "${VERSION_CODENAME:-}" = bookworm ]; then
      DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq -t bookworm-backports meson libdrm-dev >/dev/null
    else
      DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq meson libdrm-dev >/dev/null
    fi
  fi
fi

# NVK needs bindgen >= 0.65 and cbindgen newer than Debian's; built once into the cache.
tools=$cache/tools
if [ ! -x "$tools/bin/bindgen" ] || [ ! -x "$tools/bin/cbindgen" ]; then
  echo "install-compilers: building bindgen and cbindgen (a few minutes)"
  cargo install --locked --quiet --root "$tools" bindgen-cli cbindgen
fi
export PATH=$PATH:$tools/bin

# Debian's source of the installed Mesa: a deb-src entry for the suite it came from, on the
# mirror the system already uses (no host name here), then apt-get source --download-only.
work=$cache/work-$upstream-$key
rm -rf "$cache"/work-*
mkdir -p "$work"
if ! apt-cache showsrc "mesa=$version" 2>/dev/null | grep -q "^Version: $version"; then
  src=/etc/apt/sources.list.d/halftrace-src.sources
  uri=""
  if [ -f /etc/apt/sources.list.d/debian.sources ]; then
    uri=$(awk '/^URIs:/ && $2 !~ /security/ {print $2; exit}' /etc/apt/sources.list.d/debian.sources)
  fi
  if [ -z "$uri" ] && [ -f /etc/apt/sources.list ]; then
    uri=$(awk '/^deb / && $0 !~ /security/ {print $2; exit}' /etc/apt/sources.list)
  fi
  [ -n "$uri" ] || { echo "install-compilers: cannot find the configured Debian mirror" >&2; exit 1; }
  suites="${VERSION_CODENAME:-stable}"
  [ "${VERSION_CODENAME:-}" = bookworm ] && suites="bookworm bookworm-backports"
  printf 'Types: deb-src\nURIs: %s\nSuites: %s\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
    "$uri" "$suites" | $SUDO tee "$src" >/dev/null
  $SUDO apt-get update -qq
fi
# The whole Debian source where the mirror serves it; else Mesa's release tarball alone (the
# orig tarball: Debian's patches to it concern packaging, not these compilers), checked
# against the hash apt's signed index gives.
if (cd "$work" && apt-get source --download-only -qq "mesa=$version" >/dev/null 2>&1); then
  (cd "$work" && dpkg-source --no-check -x mesa_*.dsc mesa >/dev/null)
else
  echo "install-compilers: the mirror serves only Mesa's release tarball; building it without Debian's patches"
  (cd "$work" && apt-get source --download-only --tar-only -qq "mesa=$version" 2>/dev/null)
  tarball=$(ls "$work"/mesa_*.orig.tar.xz)
  mkdir "$work/mesa" && tar -xf "$tarball" -C "$work/mesa" --strip-components=1
fi
srcdir=$work/mesa
# Our patches (scripts/mesa/): to the shims only, never to a compiler.
for p in scripts/mesa/*.patch; do
  patch -d "$srcdir" -p1 --quiet <"$p"
done

# The Rust crates NVK's meson wraps name, fetched with cargo (the registry cargo is configured
# for) into meson's package cache, so meson downloads nothing.
crates=$work/crates
mkdir -p "$srcdir/subprojects/packagecache"
for w in proc-macro2 quote syn unicode-ident paste; do
  # One project per crate: the wraps pin versions that do not resolve together (syn 2.0.68
  # asks for a newer quote than the wrap's), and only the crate's own file is wanted.
  f=$(awk -F' = ' '/^source_filename/ {print $2}' "$srcdir/subprojects/$w.wrap")
  ver=${f#"$w"-}; ver=${ver%.tar.gz}
  mkdir -p "$crates/$w/src"
  : >"$crates/$w/src/lib.rs"
  printf '[package]\nname = "fetch-%s"\nversion = "0.0.0"\nedition = "2021"\n[dependencies]\n%s = "=%s"\n' \
    "$w" "$w" "$ver" >"$crates/$w/Cargo.toml"
  (cd "$crates/$w" && cargo fetch --quiet)
done
reg=${CARGO_HOME:-$HOME/.cargo}/registry/cache
for w in proc-macro2 quote syn unicode-ident paste; do
  f=$(awk -F' = ' '/^source_filename/ {print $2}' "$srcdir/subprojects/$w.wrap")
  want=$(awk -F' = ' '/^source_hash/ {print $2}' "$srcdir/subprojects/$w.wrap")
  got=$(find "$reg" -name "${f%.tar.gz}.crate" | head -1)
  [ -n "$got" ] || { echo "install-compilers: cargo did not fetch ${f%.tar.gz}" >&2; exit 1; }
  echo "$want  $got" | sha256sum -c --quiet - || { echo "install-compilers: $got does not match its wrap's hash" >&2; exit 1; }
  cp "$got" "$srcdir/subprojects/packagecache/$f"
done

# Configure every driver we want statistics from (Intel's, and its tools, only for its shim),
# build only the drivers and the shims.
build=$work/build
meson setup "$build" "$srcdir" --wrap-mode=nodownload -Dbuildtype=release -Db_ndebug=true \
  -Dplatforms= -Dglx=disabled -Degl=disabled -Dgbm=disabled -Dopengl=false -Dgles1=disabled -Dgles2=disabled \
  -Dgallium-drivers= -Dvulkan-drivers=freedreno,panfrost,nouveau,broadcom,intel -Dtools=drm-shim,intel \
  -Dvideo-codecs= -Dvulkan-layers= -Dvalgrind=disabled -Dlibunwind=disabled -Dlmsensors=disabled \
  -Dfreedreno-kmds=msm -Drust_std=2021 -Dintel-rt=disabled -Dbuild-tests=false >"$work/setup.log" 2>&1 ||
  { tail -30 "$work/setup.log" >&2; exit 1; }
drivers=(freedreno:src/freedreno/vulkan/libvulkan_freedreno.so:src/freedreno/drm-shim/libfreedreno_noop_drm_shim.so
  panfrost:src/panfrost/vulkan/libvulkan_panfrost.so:src/panfrost/drm-shim/libpanfrost_noop_drm_shim.so
  nouveau:src/nouveau/vulkan/libvulkan_nouveau.so:src/nouveau/drm-shim/libnouveau_noop_drm_shim.so
  broadcom:src/broadcom/vulkan/libvulkan_broadcom.so:src/broadcom/drm-shim/libv3d_noop_drm_shim.so
  intel::src/intel/tools/libintel_noop_drm_shim.so)
targets=()
for d in "${drivers[@]}"; do
  IFS=: read -r _ lib shim <<<"$d"
  [ -z "$lib" ] || targets+=("$lib")
  targets+=("$shim")
done
echo "install-compilers: building Mesa $version's turnip, panvk, NVK and v3dv and five drm-shims (about 15 minutes)"
ninja -C "$build" "${targets[@]}" >"$work/build.log" 2>&1 || { tail -40 "$work/build.log" >&2; exit 1; }

# Install: the libraries, and an ICD manifest per driver pointing at them (Intel's at the
# system's anv).
rm -rf "$dest.tmp"
mkdir -p "$dest.tmp/lib" "$dest.tmp/icd"
for d in "${drivers[@]}"; do
  IFS=: read -r name lib shim <<<"$d"
  cp "$build/$shim" "$dest.tmp/lib/"
  if [ -n "$lib" ]; then
    cp "$build/$lib" "$dest.tmp/lib/"
    path=$dest/lib/$(basename "$lib")
  else
    path=$(awk -F'"' '/library_path/ {print $4}' /usr/share/vulkan/icd.d/intel_icd.json)
  fi
  printf '{\n    "ICD": {\n        "api_version": "1.4.305",\n        "library_path": "%s"\n    },\n    "file_format_version": "1.0.0"\n}\n' \
    "$path" >"$dest.tmp/icd/$name.json"
done
echo "Mesa $version, built by scripts/install-compilers.sh (key $key) in $((SECONDS - t0)) s" >"$dest.tmp/complete"
rm -rf "$dest"
mv "$dest.tmp" "$dest"
rm -rf "$work"
# Builds of an older script or Mesa go (the tools stay).
for old in "$cache"/mesa-*; do
  [ "$old" = "$dest" ] || rm -rf "$old"
done
echo "install-compilers: done in $((SECONDS - t0)) s: $dest ($(du -sh "$dest" | cut -f1))"
