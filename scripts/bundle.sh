#!/usr/bin/env bash
# Makes a self-contained folder for running halftrace on a machine where nothing can be
# installed — typically an NVIDIA container started for compute only, whose driver has its
# Vulkan pieces but not the plain libraries they load at start-up:
#   halftrace (stripped), vulkaninfo, vk_probe.sh, env.sh, run-report.sh, scenes/, fonts/,
#   lib/          the Vulkan loader, glvnd EGL/GLX, X11 client libraries, Embree and TBB
#   lib/fallback/ the C++ runtime, used only where the machine has none (env.sh checks)
# Usage, from the project root on Debian/Ubuntu (after `cargo build --release`):
#   bash scripts/bundle.sh [DIR] [--scenes DIR | --no-scenes] [--tar]
# DIR defaults to target/gpu-bundle; scenes default to the repository's tests/scenes (the
# bundled teapot is always there); --tar also writes DIR.tar.gz (Embree alone is 44 MB
# unpacked) to copy over. On the GPU machine: `bash vk_probe.sh`, then
# `bash run-report.sh [BUDGET] [OUT]`, or `source env.sh; ./halftrace devices`. See docs/gpus.md.
set -euo pipefail
cd "$(dirname "$0")/.."
out=target/gpu-bundle
scenes=tests/scenes
tar=
while [ $# -gt 0 ]; do
  case "$1" in
    --scenes) scenes=$2; shift 2 ;;
    --no-scenes) scenes=; shift ;;
    --tar) tar=1; shift ;;
    -*) echo "bundle: unknown option $1" >&2; exit 1 ;;
    *) out=$1; shift ;;
  esac
done
bin=target/release/halftrace
[ -x "$bin" ] || { echo "bundle: no $bin; run cargo build --release first" >&2; exit 1; }
pkgs=(fonts-dejavu-core libvulkan1 vulkan-tools libegl1 libglvnd0 libglx0 libgl1 libx11-6 libxext6 libxcb1 libxau6 libxdmcp6 libbsd0 libmd0)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "bundle: install ${missing[*]} first (sudo apt-get install ${missing[*]})" >&2; exit 1
  fi
fi
# Refuse to empty anything that is not an earlier bundle.
if [ -e "$out" ] && [ ! -f "$out/env.sh" ] && [ -n "$(ls -A "$out" 2>/dev/null)" ]; then
  echo "bundle: $out exists and is not a bundle; name another folder" >&2; exit 1
fi
rm -rf "$out"
mkdir -p "$out/lib/fallback" "$out/scenes"
# (awk reads to the end: exiting early would fail the pipe under pipefail, now and then)
find_lib() { ldconfig -p | awk -v l="$1" '$1==l && /x86-64/ && !found {print $NF; found=1}'; }
for l in libvulkan.so.1 libEGL.so.1 libGLdispatch.so.0 libGLX.so.0 libGL.so.1 libX11.so.6 libXext.so.6 \
         libxcb.so.1 libXau.so.6 libXdmcp.so.6 libbsd.so.0 libmd.so.0; do
  f=$(find_lib "$l"); [ -n "$f" ] || { echo "bundle: $l not found" >&2; exit 1; }
  cp -L "$f" "$out/lib/$l"
done
# What the binary itself links beyond glibc: Embree and TBB always; the C++ runtime only as a
# fallback (a machine's own, possibly newer, one wins).
ldd "$bin" | awk '$2=="=>" {print $1, $3}' | while read -r name path; do
  case "$name" in
    libc.so.*|libm.so.*|libdl.so.*|libpthread.so.*|librt.so.*|ld-linux*) ;;
    libstdc++.so.*|libgcc_s.so.*) cp -L "$path" "$out/lib/fallback/$name" ;;
    *) cp -L "$path" "$out/lib/$name" ;;
  esac
done
cp "$bin" "$out/halftrace" && strip "$out/halftrace"
cp "$(command -v vulkaninfo)" "$out/vulkaninfo"
cp scripts/gpu/vk_probe.sh "$out/"
cp scenes/teapot.obj "$out/scenes/"
# The plots' labels (found beside the binary: src/report/plots.rs).
mkdir -p "$out/fonts"
cp /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf "$out/fonts/"
if [ -n "$scenes" ] && [ -d "$scenes" ]; then
  mkdir -p "$out/scenes/shared"
  find "$scenes" -maxdepth 1 \( -name '*.obj' -o -name '*.obj.gz' \) -exec cp {} "$out/scenes/shared/" \;
fi
cat > "$out/env.sh" <<'ENV'
# Source this on the GPU machine (bash): the bundle's libraries first; its C++ runtime only if
# the machine has none; the NVIDIA driver's own Vulkan manifest where the container runtime
# mounted it outside the loader's search (e.g. /usr/local/nvidia/share/vulkan/icd.d) and the
# loader would find no driver; NVIDIA's EGL vendor file (the driver's, else one written here)
# if the image lacks it. Uses no other tool.
_ht_here=${BASH_SOURCE[0]%/*}
[ "$_ht_here" = "${BASH_SOURCE[0]}" ] && _ht_here=.
_ht_here=$(cd "$_ht_here" && pwd)
_ht_path="$_ht_here/lib"
for _ht_l in "$_ht_here"/lib/fallback/*; do
  _ht_n=${_ht_l##*/}
  _ht_found=
  for _ht_d in /lib/x86_64-linux-gnu /usr/lib/x86_64-linux-gnu /lib64 /usr/lib64 /usr/lib; do
    [ -e "$_ht_d/$_ht_n" ] && _ht_found=1
  done
  [ -z "$_ht_found" ] && _ht_path="$_ht_path:$_ht_here/lib/fallback" && break
done
# Where the loader looks for drivers' manifests by itself (XDG config and data folders, /etc).
_ht_std=
_ht_ifs=$IFS
IFS=:
for _ht_d in "${XDG_CONFIG_HOME:-${HOME:-}/.config}" ${XDG_CONFIG_DIRS:-/etc/xdg} /etc \
             "${XDG_DATA_HOME:-${HOME:-}/.local/share}" ${XDG_DATA_DIRS:-/usr/local/share:/usr/share}; do
  for _ht_f in "$_ht_d"/vulkan/icd.d/*.json; do [ -e "$_ht_f" ] && _ht_std=$_ht_f; done
done
IFS=$_ht_ifs
# None there and none named: the driver's own, where container runtimes and driver containers
# mount it. Its libraries' folders go on the path too (a manifest may name a bare soname).
_ht_icd=
if [ -z "$_ht_std" ] && [ -z "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}${VK_ADD_DRIVER_FILES:-}" ]; then
  for _ht_f in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd*.json /usr/local/nvidia/etc/vulkan/icd.d/nvidia_icd*.json \
               /run/nvidia*/share/vulkan/icd.d/nvidia_icd*.json /run/nvidia*/etc/vulkan/icd.d/nvidia_icd*.json \
               /run/nvidia*/driver/usr/share/vulkan/icd.d/nvidia_icd*.json \
               /run/nvidia*/driver/etc/vulkan/icd.d/nvidia_icd*.json /opt/nvidia*/share/vulkan/icd.d/nvidia_icd*.json; do
    if [ -e "$_ht_f" ]; then _ht_icd=$_ht_f; break; fi
  done
fi
if [ -n "$_ht_icd" ]; then
  export VK_DRIVER_FILES="$_ht_icd"
  _ht_r=${_ht_icd%/*/vulkan/icd.d/*}
  for _ht_d in "$_ht_r/lib64" "$_ht_r/lib/x86_64-linux-gnu" "$_ht_r/lib"; do
    [ -d "$_ht_d" ] && _ht_path="$_ht_path:$_ht_d"
  done
fi
export LD_LIBRARY_PATH="$_ht_path${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export PATH="$_ht_here${PATH:+:$PATH}"
if [ ! -e /usr/share/glvnd/egl_vendor.d/10_nvidia.json ] && [ ! -e /etc/glvnd/egl_vendor.d/10_nvidia.json ] \
   && [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ]; then
  _ht_v=
  for _ht_f in ${_ht_icd:+"${_ht_icd%/vulkan/icd.d/*}/glvnd/egl_vendor.d/10_nvidia.json"} \
               /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json /usr/local/nvidia/etc/glvnd/egl_vendor.d/10_nvidia.json \
               /run/nvidia*/share/glvnd/egl_vendor.d/10_nvidia.json /run/nvidia*/driver/usr/share/glvnd/egl_vendor.d/10_nvidia.json; do
    if [ -e "$_ht_f" ]; then _ht_v=$_ht_f; break; fi
  done
  if [ -z "$_ht_v" ]; then
    _ht_v="${TMPDIR:-/tmp}/halftrace-10_nvidia.json"
    printf '{"file_format_version":"1.0.0","ICD":{"library_path":"libEGL_nvidia.so.0"}}\n' > "$_ht_v"
  fi
  export __EGL_VENDOR_LIBRARY_FILENAMES="$_ht_v"
fi
unset _ht_here _ht_path _ht_l _ht_n _ht_found _ht_d _ht_v _ht_std _ht_ifs _ht_f _ht_icd _ht_r
ENV
cat > "$out/run-report.sh" <<'RUN'
#!/usr/bin/env bash
# The real-GPU run in one command: bash run-report.sh [BUDGET] [OUT] [device-report flags…]
# (BUDGET default 8m; OUT default $OUT or .; the report goes to OUT/reports/<device>/, and a
# rerun after an interrupt finishes it). Uses no tool but bash and the bundle's.
set -u
budget=${1:-8m}; dest=${2:-${OUT:-.}}
shift $(( $# < 2 ? $# : 2 ))
case "$dest" in /*) ;; *) dest="$PWD/$dest" ;; esac
here=$(cd "${BASH_SOURCE[0]%/*}" 2>/dev/null && pwd || pwd)
cd "$here"
source ./env.sh
./halftrace devices
extra=()
[ -d scenes/shared ] && extra=(--scenes-dir scenes/shared)
# --resume: a report interrupted earlier (same device and settings) is finished, not redone.
./halftrace device-report --budget "$budget" --scene scenes/teapot.obj "${extra[@]}" --resume \
  --reports "$dest/reports" "$@"
RUN
chmod +x "$out/run-report.sh"
du -sh "$out" | awk '{print "bundle: " $2 " holds " $1}'
if [ -n "$tar" ]; then
  tar czf "$out.tar.gz" -C "$(dirname "$out")" "$(basename "$out")"
  du -sh "$out.tar.gz" | awk '{print "bundle: " $2 " is " $1 " (tar xzf it on the GPU machine)"}'
fi
