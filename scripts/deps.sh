#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Install the Debian 12 packages ivdb needs, only those that are missing (idempotent, quick).
set -euo pipefail

packages=(
  cmake g++ ccache make pkg-config
  libopenvdb-dev libboost-iostreams-dev libtbb-dev libblosc-dev liblz4-dev zlib1g-dev libimath-dev
  libcli11-dev nlohmann-json3-dev
  libgtest-dev libbenchmark-dev
  libopenvdb-tools python3-openvdb python3-numpy python3-matplotlib python3-scipy libpng-dev libopenexr-dev
  libnanovdb-dev libnanovdb-tools libassimp-dev
  openmpi-bin libopenmpi-dev
  blender
  clang libclang-rt-14-dev llvm
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -gt 0 ]; then
  echo "ivdb set-up: installing ${missing[*]}" >&2
  sudo_cmd=()
  if [ "$(id -u)" -ne 0 ]; then
    if ! command -v sudo >/dev/null; then
      echo "ivdb set-up: missing packages ${missing[*]}; run as root or install sudo" >&2
      exit 1
    fi
    sudo_cmd=(sudo)
  fi
  "${sudo_cmd[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
