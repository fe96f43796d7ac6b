#!/usr/bin/env bash
# apt-get installs those of the given Debian packages that are missing (needs root then);
# nothing is fetched when all are present. Used by install-deps.sh and install-fuzz-deps.sh.
#   tools/apt-ensure.sh LABEL PACKAGE...
set -euo pipefail
label=$1
shift
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  if [ "$(id -u)" -ne 0 ]; then
    echo "$label: need root to apt-get install: ${missing[*]}" >&2
    exit 1
  fi
  echo "$label: apt-get install ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
