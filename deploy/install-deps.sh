#!/usr/bin/env bash
# Installs every build, test and run dependency of stevi from Debian 12 (bookworm) packages.
# Idempotent and non-interactive: packages already present are left alone.
# Usage: deploy/install-deps.sh            (as root, or with sudo available)
set -euo pipefail

packages=(
  build-essential cmake pkg-config git
  libopencv-dev libopencv-contrib-dev
  libeigen3-dev
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libgeographiclib-dev
  libaravis-dev libusb-1.0-0-dev aravis-tools iproute2 util-linux openssl
  libcivetweb-dev civetweb nlohmann-json3-dev libjs-leaflet chromium
  libgtest-dev libgmock-dev libbenchmark-dev systemd
  clang-format clang-tidy eslint
  clang libfuzzer-14-dev libclang-rt-14-dev
  libgstreamer1.0-dev libgstreamer-plugins-base1.0-dev libgstrtspserver-1.0-dev
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-tools
  libzstd-dev liblz4-dev zlib1g-dev
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages already installed"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then sudo_cmd=(sudo); else
    echo "install-deps: need root (or sudo) to install: ${missing[*]}" >&2; exit 1
  fi
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -q
"${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "install-deps: done"
