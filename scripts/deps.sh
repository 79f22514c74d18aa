#!/bin/sh
# Install the Debian (bookworm) packages ARMSTG builds and tests against.
# Run as root: installs what is missing with apt-get.  Otherwise: prints the
# exact command to run and exits non-zero if anything is missing.
set -eu
PKGS="build-essential pkg-config libnifti2-dev libniftiio-dev libhdf5-dev \
libmsgpack-dev libinih-dev zlib1g-dev libpng-dev libcmocka-dev libzmq3-dev \
clang libclang-rt-14-dev python3 python3-venv libfftw3-dev \
libczmq-dev libsodium-dev liblapacke-dev libopenblas-dev"
missing=""
for p in $PKGS; do
    if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
        missing="$missing $p"
    fi
done
[ -z "$missing" ] && exit 0
if [ "$(id -u)" = 0 ]; then
    echo "deps: installing:$missing"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >/dev/null
    # shellcheck disable=SC2086
    apt-get install -y -qq --no-install-recommends $missing >/dev/null
    echo "deps: done"
else
    echo "deps: missing Debian packages:$missing" >&2
    echo "deps: run:  sudo apt-get install -y$missing" >&2
    exit 1
fi
