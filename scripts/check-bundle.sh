#!/usr/bin/env bash
# Proves a bundle (scripts/bundle.sh) runs where nothing is installed: builds a root holding
# only glibc, bash and a Vulkan driver (lavapipe and its own libraries, the stand-in for a GPU
# driver the container runtime mounts), copies the bundle in, and runs `halftrace devices`
# and `halftrace device-report` there with an empty environment (env -i), then `devices` again
# with the driver's manifest only at NVIDIA's container path (/usr/local/nvidia/share/vulkan/
# icd.d/nvidia_icd.json), which env.sh must find. No Vulkan loader,
# no glvnd, no Embree, no TBB, no validation layer exist in that root but the bundle's.
# Needs root (chroot). Usage: sudo bash scripts/check-bundle.sh [BUNDLE] [BUDGET]
# (BUNDLE default target/gpu-bundle, BUDGET default 1s: one sweep job). Prints what it ran.
set -euo pipefail
cd "$(dirname "$0")/.."
bundle=$(cd "${1:-target/gpu-bundle}" && pwd)
budget=${2:-1s}
[ -f "$bundle/env.sh" ] || { echo "check-bundle: $bundle is not a bundle (run scripts/bundle.sh)" >&2; exit 1; }
[ "$(id -u)" = 0 ] || { echo "check-bundle: needs root (chroot)" >&2; exit 1; }
root=$(mktemp -d /tmp/halftrace-root.XXXXXX)
cleanup() { umount "$root/proc" "$root/cache" 2>/dev/null || true; rm -rf "$root"; }
trap cleanup EXIT
copy() { # files and the libraries they link, at their own paths (symlinks resolved)
  for f in "$@"; do
    cp --parents -L "$f" "$root"
    ldd "$f" 2>/dev/null | awk '$2=="=>" && $3 ~ /^\// {print $3} $1 ~ /^\// {print $1}' |
      while read -r d; do [ -e "$root$d" ] || cp --parents -L "$d" "$root"; done
  done
}
driver=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["ICD"]["library_path"])' \
  /usr/share/vulkan/icd.d/lvp_icd.json)
case "$driver" in
  /*) ;;
  *) driver=$(ldconfig -p | awk -v l="$driver" '$1==l && /x86-64/ && !f {print $NF; f=1}') ;;
esac
copy /bin/bash "$driver"
mkdir -p "$root/usr/share/vulkan/icd.d" "$root/tmp" "$root/dev" "$root/proc" "$root/cache"
cp /usr/share/vulkan/icd.d/lvp_icd.json "$root/usr/share/vulkan/icd.d/"
mknod -m 666 "$root/dev/null" c 1 3
mknod -m 666 "$root/dev/urandom" c 1 9
mount -t proc proc "$root/proc"
# The pipeline cache of this machine, so that the check does not recompile every kernel.
# (Mesa keeps it in a folder under MESA_SHADER_CACHE_DIR, by default under ~/.cache.)
cache=${MESA_SHADER_CACHE_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}}
mkdir -p "$cache"; mount --bind "$cache" "$root/cache"
cp -a "$bundle" "$root/bundle"
echo "check-bundle: root $root: $(find "$root" \( -path "$root/proc" -o -path "$root/cache" \) -prune -o -type f -print | wc -l) files; loader, glvnd, Embree, TBB outside the bundle:"
find "$root" \( -path "$root/bundle" -o -path "$root/proc" -o -path "$root/cache" \) -prune -o \( -name 'libvulkan.so*' -o -name 'libEGL*' -o -name 'libGLX*' \
  -o -name 'libembree*' -o -name 'libtbb*' -o -name '*VkLayer*' -o -name 'DejaVu*' \) -print | sed 's/^/  /' | grep . || echo "  none"
run() { chroot "$root" /usr/bin/env -i HOME=/tmp TMPDIR=/tmp MESA_SHADER_CACHE_DIR=/cache /bin/bash -c "$1"; }
[ -x "$root/usr/bin/env" ] || copy /usr/bin/env
echo "== env -i: source env.sh; halftrace devices"
run 'cd /bundle && source ./env.sh && echo "LD_LIBRARY_PATH=$LD_LIBRARY_PATH" && halftrace devices'
echo "== env -i: bash run-report.sh $budget /tmp/out --width 16 --height 16"
run "cd /bundle && bash run-report.sh $budget /tmp/out --width 16 --height 16"
echo "== the driver's own manifest where a container runtime mounts NVIDIA's: lavapipe's manifest moved"
echo "   to /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json, none where the loader looks by itself"
mkdir -p "$root/usr/local/nvidia/share/vulkan/icd.d"
mv "$root/usr/share/vulkan/icd.d/lvp_icd.json" "$root/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json"
run 'cd /bundle && source ./env.sh && echo "VK_DRIVER_FILES=$VK_DRIVER_FILES" && halftrace devices' | tee "$root/tmp/fake.txt"
grep -q '^VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json$' "$root/tmp/fake.txt" &&
  grep -q llvmpipe "$root/tmp/fake.txt" || { echo "check-bundle: env.sh did not find the driver's manifest" >&2; exit 1; }
mv "$root/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json" "$root/usr/share/vulkan/icd.d/lvp_icd.json"
echo "== what it wrote (the report's first lines)"
ls "$root"/tmp/out/reports/*/
head -20 "$root"/tmp/out/reports/*/report.md
