#!/usr/bin/env bash
# Installs what `make fuzz` needs on top of tools/install-deps.sh, on Debian 12 as root:
# clang 14 with its libFuzzer/sanitizer runtimes (libclang-rt-14-dev) and llvm-symbolizer
# (llvm-14) for readable stack traces. Idempotent: nothing is fetched when all are present.
set -euo pipefail
bash "$(dirname "$0")/apt-ensure.sh" install-fuzz-deps clang-14 libclang-rt-14-dev llvm-14
