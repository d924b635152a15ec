#!/usr/bin/env bash
# Installs the system packages halftrace needs on Debian bookworm (or Ubuntu),
# idempotently: Mesa's lavapipe from bookworm-backports (shaderFloat16, 16-bit
# storage, VK_KHR_ray_query), the Vulkan loader, shaderc/glslang/SPIRV-Tools for
# static linking, Embree 3 (the host-CPU baseline), the Khronos validation layer for
# the test suite, and SwiftShader (a second CPU Vulkan, from Debian's chromium-common: its
# ICD is /usr/lib/chromium/vk_swiftshader_icd.json; no browser) for the conformance legs.
# Backports reuse the mirror already configured for the system (no host names here).
set -euo pipefail
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

pkgs=(libvulkan-dev vulkan-tools libshaderc-dev glslang-dev spirv-tools vulkan-validationlayers libembree-dev pkg-config fonts-dejavu-core git)

missing=()
# SwiftShader: Debian ships it in chromium-common (installed without its desktop
# recommends); where no such package exists (Ubuntu's chromium is a snap) it is not asked
# for, everything else installs, and `halftrace` never needs it (CI's SwiftShader leg does).
swiftshader=chromium-common
. /etc/os-release
want=("${pkgs[@]}" mesa-vulkan-drivers)
if [ "${VERSION_CODENAME:-}" = bookworm ] || apt-cache show "$swiftshader" >/dev/null 2>&1; then
  want+=("$swiftshader")
fi

for p in "${want[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# lavapipe must be Mesa >= 24 for shaderFloat16 and ray queries.
mesa_ok=0
if v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null); then
  major=${v%%.*}; major=${major##*:}
  [ "${major:-0}" -ge 24 ] 2>/dev/null && mesa_ok=1
fi

if [ ${#missing[@]} -eq 0 ] && [ $mesa_ok -eq 1 ]; then
  echo "install-deps: system packages already present"
  exit 0
fi

if [ "${VERSION_CODENAME:-}" = bookworm ]; then
  src=/etc/apt/sources.list.d/halftrace-backports.sources
  if [ ! -f "$src" ]; then
    uri=""
    if [ -f /etc/apt/sources.list.d/debian.sources ]; then
      uri=$(awk '/^URIs:/ && $2 !~ /security/ {print $2; exit}' /etc/apt/sources.list.d/debian.sources)
    fi
    if [ -z "$uri" ] && [ -f /etc/apt/sources.list ]; then
      uri=$(awk '/^deb / && $0 !~ /security/ {print $2; exit}' /etc/apt/sources.list)
    fi
    [ -n "$uri" ] || { echo "install-deps: cannot find the configured Debian mirror" >&2; exit 1; }
    printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' "$uri" | $SUDO tee "$src" >/dev/null
  fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${pkgs[@]}"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$swiftshader"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers
else
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${pkgs[@]}" mesa-vulkan-drivers
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$swiftshader" ||
    echo "install-deps: no $swiftshader here: SwiftShader (a second CPU Vulkan) is not installed" >&2
fi
echo "install-deps: done"
