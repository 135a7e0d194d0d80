#!/usr/bin/env bash
# Container entrypoint: source the catkin devel space of the built tree, then
# roslaunch PACKAGE LAUNCHFILE with the remaining arguments (name:=value).
set -euo pipefail
PKG="$1"; LAUNCH="$2"; shift 2
# shellcheck disable=SC1091
source /hermes/build/devel/setup.bash
exec roslaunch "$PKG" "$LAUNCH" "$@"
