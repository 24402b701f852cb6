#!/usr/bin/env bash
# Set up lightfast on this machine: Debian libraries, a Python 3.11 venv with the pinned ROS 2 Jazzy wheels and
# libraries of requirements.lock, this checkout installed into it (editable), and the ROS interface packages
# PyPI has no wheels for (tf2_msgs), built by scripts/build_interfaces.sh into a cache beside the venv.
#
# Idempotent and fast when nothing changed: the venv lives in ${LIGHTFAST_VENV_ROOT:-~/.cache/lightfast}/venv-<hash>,
# keyed by the hash of requirements.lock and the interpreter, and is reused by every checkout with the same lock.
# `.venv` in the checkout is a symlink to it. Prints nothing but progress on stderr; exit code 0 on success.
#
# Environment: LIGHTFAST_PYTHON (interpreter, default python3.11 or python3), LIGHTFAST_VENV_ROOT (cache dir).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
say() { printf 'lightfast setup: %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

py=${LIGHTFAST_PYTHON:-}
if [ -z "$py" ]; then
  for cand in python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1; then py=$cand; break; fi
  done
fi
[ -n "$py" ] || die "no python3 found; install Python 3.11 (Debian 12: apt-get install python3 python3-venv)"
pyver=$("$py" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
[ "$pyver" = "3.11" ] || die "Python 3.11 is required (ROS 2 Jazzy wheels), $py is $pyver; set LIGHTFAST_PYTHON"

# Debian libraries: open3d needs libusb-1.0.
if ! /sbin/ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing Debian package libusb-1.0-0 (needed by open3d)"
    apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1 || {
      apt-get update -qq >/dev/null && apt-get install -y -qq libusb-1.0-0 >/dev/null; } \
      || die "apt-get install libusb-1.0-0 failed"
  else
    die "open3d needs the system library libusb-1.0; install it as root: sudo apt-get install libusb-1.0-0"
  fi
fi

lock="$root/requirements.lock"
hash=$( { cat "$lock"; "$py" -c 'import sys, platform; print(sys.version, platform.machine())'; } \
        | sha256sum | cut -c1-16)
venv_root=${LIGHTFAST_VENV_ROOT:-${XDG_CACHE_HOME:-$HOME/.cache}/lightfast}
venv="$venv_root/venv-$hash"
mkdir -p "$venv_root"

# One setup at a time per venv (two test runs may start together).
exec 9>"$venv.lock"
flock 9

if [ ! -f "$venv/.complete" ]; then
  say "building venv $venv from requirements.lock (first time only, about 2 minutes)"
  rm -rf "$venv"
  "$py" -m venv "$venv"
  log="$venv_root/pip-$hash.log"
  { "$venv/bin/python" -m pip install --disable-pip-version-check --upgrade "pip==24.3.1" \
    && "$venv/bin/python" -m pip install --disable-pip-version-check -r "$lock"; } >"$log" 2>&1 \
    || { tail -n 20 "$log" >&2; die "pip install failed (full log: $log)"; }
  touch "$venv/.complete"
fi

# Install this checkout (editable) unless the venv already points here with the same entry points.
stamp="$root $(cat "$root/setup.py" "$root/setup.cfg" | sha256sum | cut -c1-16)"
if [ "$(cat "$venv/.checkout" 2>/dev/null)" != "$stamp" ] \
   || ! (cd / && "$venv/bin/python" -c \
         'import lightfast, sys; sys.exit(0 if lightfast.__file__.startswith(sys.argv[1]) else 1)' "$root/") 2>/dev/null
then
  say "installing this checkout ($root) into the venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation --use-pep517 -e "$root" \
    >"$venv_root/pip-editable.log" 2>&1 || { tail -n 20 "$venv_root/pip-editable.log" >&2; die "installing $root failed"; }
  printf '%s\n' "$stamp" > "$venv/.checkout"
fi

# ROS interface packages that PyPI has no wheel for (tf2_msgs), built once into a cache beside the venv and
# linked into it; a quick check when the cache is complete. See scripts/build_interfaces.sh.
bash "$root/scripts/build_interfaces.sh" "$venv" "$py"

ln -sfn "$venv" "$root/.venv"
