#!/usr/bin/env bash
# Installs what photopose needs from Debian on a fresh machine (idempotent,
# non-interactive). The Rust toolchain itself (cargo, rustc) must already be
# there. Packages are added here as crates need them (libaravis for the GigE
# source, systemd for the unit checks).
set -euo pipefail

PACKAGES=(pkg-config systemd libaravis-dev libusb-1.0-0-dev libglib2.0-dev aravis-tools aravis-tools-cli)

command -v cargo >/dev/null || { echo "deps: cargo is missing: install the Rust toolchain first" >&2; exit 1; }

missing=()
for p in "${PACKAGES[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
echo "deps: all installed (${PACKAGES[*]})"
