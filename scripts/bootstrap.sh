#!/usr/bin/env bash
# Set up GeoMDP in ./.venv on a fresh Debian/Ubuntu machine (or refresh an existing one).
#   - system packages: gfortran (escnn's py3nj builds from source), EGL + Mesa (headless rendering)
#   - a virtual environment with the pinned dependencies and this project (editable, with test extras)
# Re-running is cheap: pip is skipped while pyproject.toml is unchanged.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${GEOMDP_VENV:-.venv}
PYTHON=${PYTHON:-python3}

missing=()
command -v gfortran >/dev/null 2>&1 || missing+=(gfortran)
ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' || missing+=(libegl1)
compgen -G "/usr/lib/*/dri/swrast_dri.so" >/dev/null || compgen -G "/usr/lib/*/dri/*_dri.so" >/dev/null \
  || missing+=(libgl1-mesa-dri)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "bootstrap: installing system packages: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "bootstrap: missing system packages: ${missing[*]} (install them, e.g. with apt-get)" >&2
    exit 1
  fi
fi

[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
stamp="$VENV/.geomdp-installed"
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "bootstrap: installing Python dependencies into $VENV (first time: a few minutes)"
  "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e ".[test]" 2>&1 \
    | grep -v "^WARNING: Location" || true
  "$VENV/bin/python" -c "import geomdp_envs, torchrl, escnn, dm_control" \
    || { echo "bootstrap: install failed" >&2; exit 1; }
  echo "$want" > "$stamp"
fi
