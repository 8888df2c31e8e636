#!/usr/bin/env bash
# Installs what the `dsec` feature (DSEC events.h5 input) needs on Debian 12: the HDF5 library
# with its headers and pkg-config file (hdf5-metno links against it) and the Blosc HDF5 filter
# plugin, which DSEC's files are compressed with (HDF5 loads it from its default plugin
# directory, /usr/lib/x86_64-linux-gnu/hdf5/serial/plugins). Idempotent: a quick check when
# everything is already installed.
set -euo pipefail

packages=(libhdf5-dev hdf5-filter-plugin-blosc-serial pkg-config)
missing=()
for package in "${packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$package")
    fi
done
if [ ${#missing[@]} -eq 0 ]; then
    echo "setup-hdf5: ${packages[*]} already installed"
    exit 0
fi
echo "setup-hdf5: installing ${missing[*]}"
if [ "$(id -u)" -ne 0 ]; then
    echo "setup-hdf5: need root to apt-get install ${missing[*]}" >&2
    exit 1
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "setup-hdf5: installed ${missing[*]}"
