#!/usr/bin/env bash
# Build the ROS 2 interface packages of interfaces/ and make the lightfast venv import them.
#
# Why this exists: lightfast gets ROS 2 Jazzy from PyPI wheels, and PyPI has wheels for rclpy and the
# common_interfaces (geometry_msgs, sensor_msgs, ...) but none for tf2_msgs, the package of
# tf2_msgs/msg/TFMessage that /tf and /tf_static carry. So tf2_msgs is built here from its upstream message
# definition (interfaces/tf2_msgs/) with the ament_cmake/rosidl toolchain that PyPI does carry, exactly as
# colcon would build it, against the same wheel versions the venv runs (requirements.lock as constraints), so
# the generated typesupport libraries are ABI-compatible with the venv's rclpy and rmw_fastrtps_cpp.
#
# Usage: build_interfaces.sh VENV PYTHON   (called by scripts/setup.sh once the venv exists)
#   VENV    the lightfast venv; PYTHON the base interpreter it was made from.
#
# Cache: DIR/interfaces-<hash>/ beside the venv (DIR is the venv's parent, ~/.cache/lightfast by default), keyed
# by the hash of interfaces/**, this script, requirements.lock and the interpreter. It keeps install/ (the ament
# install prefix: lib/, lib/pythonX.Y/site-packages/, share/), build.log and .complete; the build environment
# (a venv with interfaces/build-requirements.txt, ~150 MB) and the build trees are deleted after a good build.
# When the cache is complete this script only checks the two links below: no Python, no build.
#
# How the venv finds the packages (both links are rewritten when they do not match):
#   site-packages/lightfast_interfaces.pth   names install/lib/pythonX.Y/site-packages, so `import tf2_msgs` works;
#   site-packages/ros_lightfast_interfaces.libs -> install/lib, a symlink. The ros-wheels-bootstrapper .pth puts
#     every site-packages/ros_*.libs directory on LD_LIBRARY_PATH and re-executes Python at start-up. The libraries
#     must be on LD_LIBRARY_PATH (an RPATH would not do): rosidl_typesupport_c loads
#     libtf2_msgs__rosidl_typesupport_fastrtps_c.so at run time by searching LD_LIBRARY_PATH for it.
#
# Progress on stderr; on failure one error line after the tail of the build log, exit code 1.
set -euo pipefail

# The packages of interfaces/ in dependency order (a later one may depend on an earlier one).
packages=(tf2_msgs)

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
say() { printf 'lightfast setup: %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

[ $# -eq 2 ] || die "usage: build_interfaces.sh VENV PYTHON"
venv=$(cd "$1" && pwd -P)
py=$2

interp=$("$py" -c 'import sys, platform; print(sys.version, platform.machine()); print("%d.%d" % sys.version_info[:2])')
pyver=${interp##*$'\n'}
hash=$( { cd "$root" && find interfaces -type f -print0 | LC_ALL=C sort -z | xargs -0 sha256sum \
          && sha256sum scripts/build_interfaces.sh requirements.lock && printf '%s\n' "$interp"; } \
        | sha256sum | cut -c1-16)
cache="$(dirname "$venv")/interfaces-$hash"
install="$cache/install"
site="$venv/lib/python$pyver/site-packages"
[ -d "$site" ] || die "no site-packages in the venv: $site"

# Point the venv at install/ (idempotent; touches nothing when the links are already right).
link_venv() {
  local pth="$site/lightfast_interfaces.pth" libs="$site/ros_lightfast_interfaces.libs"
  local want="$install/lib/python$pyver/site-packages"
  if [ "$(cat "$pth" 2>/dev/null)" != "$want" ]; then printf '%s\n' "$want" > "$pth"; fi
  if [ "$(readlink "$libs" 2>/dev/null)" != "$install/lib" ]; then ln -sfn "$install/lib" "$libs"; fi
}

if [ -f "$cache/.complete" ]; then
  link_venv
  exit 0
fi

# One build at a time per cache directory.
exec 8>"$cache.lock"
flock 8
if [ -f "$cache/.complete" ]; then
  link_venv
  exit 0
fi

# The toolchain: a C/C++ compiler, make, CMake and the interpreter's headers.
missing_tools() {
  local t inc
  for t in cc c++ make cmake; do command -v "$t" >/dev/null 2>&1 || printf '%s ' "$t"; done
  inc=$("$py" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  [ -f "$inc/Python.h" ] || printf '%s ' "Python.h"
}
missing=$(missing_tools)
if [ -n "$missing" ]; then
  debs="build-essential cmake python$pyver-dev"
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing Debian packages $debs (to build tf2_msgs; missing: ${missing% })"
    apt-get install -y -qq $debs >/dev/null 2>&1 || {
      apt-get update -qq >/dev/null && apt-get install -y -qq $debs >/dev/null; } \
      || die "apt-get install $debs failed"
    missing=$(missing_tools)
  fi
  [ -z "$missing" ] || die "building tf2_msgs needs a C/C++ compiler, make, CMake and the Python headers" \
    "(missing: ${missing% }); install them as root: apt-get install $debs"
fi

say "building ROS interfaces (${packages[*]}) in $cache (first time only, about 40 s)"
rm -rf "$cache"
mkdir -p "$cache"
log="$cache/build.log"
benv="$cache/buildenv"
fail() { tail -n 25 "$log" >&2; die "$* (full log: $log)"; }

{ "$py" -m venv "$benv" \
  && "$benv/bin/python" -m pip install --disable-pip-version-check --upgrade "pip==24.3.1" \
  && "$benv/bin/python" -m pip install --disable-pip-version-check \
       -c "$root/requirements.lock" -r "$root/interfaces/build-requirements.txt"; } >"$log" 2>&1 \
  || fail "installing the rosidl/ament build toolchain into $benv failed"

for pkg in "${packages[@]}"; do
  say "  building $pkg"
  # The build sees the build environment and the packages installed before it, nothing of the caller's.
  ( export PATH="$benv/bin:$PATH" AMENT_PREFIX_PATH="$install:$benv" CMAKE_PREFIX_PATH="$install:$benv" \
           LD_LIBRARY_PATH="$install/lib:$benv/lib"
    unset PYTHONPATH PYTHONHOME
    cmake -S "$root/interfaces/$pkg" -B "$cache/build/$pkg" \
      -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF -DCMAKE_INSTALL_PREFIX="$install" \
      -DPython3_EXECUTABLE="$benv/bin/python" \
      -DCMAKE_PROJECT_INCLUDE="$root/interfaces/pypi_wheel_fixups.cmake" \
    && cmake --build "$cache/build/$pkg" --parallel "$(nproc)" \
    && cmake --install "$cache/build/$pkg" ) >>"$log" 2>&1 \
    || fail "building the ROS interface package $pkg failed"
done

link_venv
# Check that the venv's own runtime imports the messages and serializes one through the Fast DDS typesupport
# (the re-executing bootstrapper must see a clean environment to put the .libs directory on LD_LIBRARY_PATH).
(cd / && env -u _ROS_WHEELS_BOOTSTRAP_COMPLETE -u LD_LIBRARY_PATH -u PYTHONPATH "$venv/bin/python" -c '
from rclpy.serialization import deserialize_message, serialize_message
from tf2_msgs.msg import TFMessage
assert deserialize_message(serialize_message(TFMessage()), TFMessage) == TFMessage()
print("tf2_msgs imported and serialized by", __import__("tf2_msgs").__file__)
') >>"$log" 2>&1 || fail "tf2_msgs was built but the venv cannot use it"

rm -rf "$benv" "$cache/build"
touch "$cache/.complete"
say "ROS interfaces ready: $install"
