#!/bin/sh
# The extension image's Python install (blueos/Dockerfile), also run in a plain venv by
# tests/test_blueos.py:  TARGETPLATFORM=linux/amd64 sh blueos/install.sh SRC VENV
#
# The wheel of the source tree SRC (built by the venv's pip, as `make install` builds it:
# onboard/apps/install.py), installed into VENV with the configs and gains bundled inside.
# Only the service's own dependencies (no extra: the vehicle install stays lean). numpy,
# scipy and msgspec only as wheels (a source build of scipy under emulation takes hours).
# linux/arm/v7: PyPI has no armv7l wheel of numpy, scipy, msgspec or pymavlink; piwheels
# builds them for Debian bookworm and Python 3.11 (the image's), and pymavlink builds
# without its optional C extension if piwheels has no wheel of it.
set -eu
src=$1
venv=$2
python3 -m venv "$venv"
pip="$venv/bin/python -m pip"
$pip install --quiet --upgrade pip
dist=$(mktemp -d)
$pip wheel --quiet --no-deps --wheel-dir "$dist" "$src"
wheel=$(ls "$dist"/onboard-*.whl)
case "${TARGETPLATFORM:-}" in
    linux/arm/v7)
        DISABLE_MAVNATIVE=True $pip install --quiet \
            --extra-index-url https://www.piwheels.org/simple \
            --only-binary numpy,scipy,msgspec "$wheel"
        ;;
    *)
        $pip install --quiet --only-binary numpy,scipy,msgspec "$wheel"
        ;;
esac
rm -rf "$dist"
"$venv/bin/onboard" --help > /dev/null
