#!/bin/sh
# The extension image's Python install (blueos/Dockerfile), also run in a plain venv by
# tests/test_blueos.py:  TARGETPLATFORM=linux/amd64 sh blueos/install.sh SRC VENV
#
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
case "${TARGETPLATFORM:-}" in
    linux/arm/v7)
        DISABLE_MAVNATIVE=True $pip install --quiet \
            --extra-index-url https://www.piwheels.org/simple \
            --only-binary numpy,scipy,msgspec "$src"
        ;;
    *)
        $pip install --quiet --only-binary numpy,scipy,msgspec "$src"
        ;;
esac
"$venv/bin/onboard" --help > /dev/null
