#!/bin/sh
# The extension's start: the bundled configuration of the vehicle class in ONBOARD_VEHICLE
# (twin-thruster-boat for a BlueBoat, bluerov2, ...: a name, found inside the installed
# package, as `onboard replay --config NAME` finds it), then the extension's own file in the
# data folder (copied there at the first start; the web page edits it). State and
# recordings go to the data folder too (/usr/blueos/extensions/onboard on the vehicle;
# ONBOARD_DATA_DIR, default /data inside the container).
set -eu
data=${ONBOARD_DATA_DIR:-/data}
vehicle=${ONBOARD_VEHICLE:-twin-thruster-boat}
mkdir -p "$data"
[ -f "$data/onboard.toml" ] || cp /opt/onboard/blueos/onboard.toml "$data/onboard.toml"
exec /opt/onboard/venv/bin/onboard run --config "$vehicle" \
    --config "$data/onboard.toml" --state-dir "$data"
