#!/usr/bin/env bash
# Installs what photopose needs from Debian on a fresh machine (idempotent,
# non-interactive). The Rust toolchain itself (cargo, rustc) must already be
# there. Packages are added here as crates need them (libaravis for the GigE
# source, systemd for the unit checks, prometheus for `promtool check metrics`).
set -euo pipefail

# libaravis-dev does not pull libusb-1.0-0-dev, yet aravis-0.8.pc requires it
# (without it: a misleading "system library `aravis-0.8` not found").
PACKAGES=(pkg-config systemd libaravis-dev libusb-1.0-0-dev libglib2.0-dev aravis-tools aravis-tools-cli prometheus)

command -v cargo >/dev/null || { echo "deps: cargo is missing: install the Rust toolchain first" >&2; exit 1; }

missing=()
for p in "${PACKAGES[@]}"; do
    # "installed", not merely known (a removed package keeps a dpkg status).
    [ "$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null)" = "install ok installed" ] || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
echo "deps: all installed (${PACKAGES[*]})"
