#!/bin/sh
# Builds the Debian package: the release binary, its man pages and shell
# completions generated from the CLI, then `cargo deb` (metadata in
# Cargo.toml, [package.metadata.deb]). Needs `cargo install cargo-deb`.
# The .deb lands in target/debian/.
set -eu
cd "$(dirname "$0")/.."
cargo build --release --locked
assets=target/assets
rm -rf "$assets"
target/release/photopose generate man --out "$assets/man"
gzip -9n "$assets"/man/*.1
for shell in bash zsh fish; do
    target/release/photopose generate completions "$shell" --out "$assets/completions"
done
cargo deb --no-build --locked "$@"
