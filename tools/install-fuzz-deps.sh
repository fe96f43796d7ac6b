#!/usr/bin/env bash
# Installs what `make fuzz` needs on top of tools/install-deps.sh, on Debian 12 as root:
# clang 14 with its libFuzzer/sanitizer runtimes (libclang-rt-14-dev) and llvm-symbolizer
# (llvm-14) for readable stack traces. Idempotent: nothing is fetched when all are present.
set -euo pipefail
APT_PACKAGES=(clang-14 libclang-rt-14-dev llvm-14)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  if [ "$(id -u)" -ne 0 ]; then
    echo "install-fuzz-deps: need root to apt-get install: ${missing[*]}" >&2
    exit 1
  fi
  echo "install-fuzz-deps: apt-get install ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
