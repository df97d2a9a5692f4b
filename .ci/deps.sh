#!/usr/bin/env bash
# Installs what photopose needs from Debian on a fresh machine (idempotent,
# non-interactive). The Rust toolchain itself (cargo, rustc) must already be
# there. Packages are added here as crates need them (libaravis for the GigE
# source, systemd for the unit checks, prometheus for `promtool check metrics`),
# and the third-party GenTL producer the GenTL tests run against (viky.cti,
# from the official `genicam` wheel; nothing of Python is used at run time).
set -euo pipefail

# libaravis-dev does not pull libusb-1.0-0-dev, yet aravis-0.8.pc requires it
# (without it: a misleading "system library `aravis-0.8` not found").
PACKAGES=(pkg-config systemd libaravis-dev libusb-1.0-0-dev libglib2.0-dev aravis-tools aravis-tools-cli prometheus)

command -v cargo >/dev/null || { echo "deps: cargo is missing: install the Rust toolchain first" >&2; exit 1; }

# pip and unzip fetch and open the genicam wheel (only if not there).
command -v pip3 >/dev/null || command -v pip >/dev/null || PACKAGES+=(python3-pip)
command -v unzip >/dev/null || PACKAGES+=(unzip)

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

# viky.cti: where tests/daemon_gentl.rs and crates/gentl/tests/viky.rs look
# for it (they skip, saying so, when it is absent).
GENTL_DIR=/opt/photopose-test/gentl
GENICAM_WHEEL=genicam==1.6.0
if [ ! -f "$GENTL_DIR/viky.cti" ]; then
    pip=$(command -v pip3 || command -v pip)
    tmp=$(mktemp -d)
    "$pip" download --quiet --no-deps --disable-pip-version-check "$GENICAM_WHEEL" -d "$tmp"
    mkdir -p "$GENTL_DIR"
    unzip -q -j -o "$tmp"/genicam-*.whl '*/viky.cti' -d "$GENTL_DIR"
    rm -rf "$tmp"
fi
echo "deps: GenTL test producer at $GENTL_DIR/viky.cti"

# rosbags (pure Python, PyPI): the Zenoh test decodes the ROS 2 CDR messages
# with it, an implementation independent of the daemon's encoder
# (tests/zenoh_cli.rs looks here and skips that check, saying so, without it).
PYTHON_DIR=/opt/photopose-test/python
ROSBAGS=rosbags==0.11.9
if ! PYTHONPATH="$PYTHON_DIR" python3 -c "import rosbags" 2>/dev/null; then
    pip=$(command -v pip3 || command -v pip)
    "$pip" install --quiet --disable-pip-version-check --target "$PYTHON_DIR" "$ROSBAGS"
fi
echo "deps: rosbags at $PYTHON_DIR"
