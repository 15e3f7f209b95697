#!/usr/bin/env bash
# Creates (or refreshes) the project's virtual environment in .venv and installs ftc-hw into it,
# fetches the vendor meshes the built-in scenes name, then compiles its numba kernels into numba's
# on-disk cache (`ftc warm`, a progress line per step).
# Re-runs pip only when pyproject.toml changed since the last successful install, and the warm-up
# only after an install or when a source file is newer than the last warm-up (numba's cache index
# then recompiles just the kernels whose sources changed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
py="${FTC_PYTHON:-}"
if [ -z "$py" ]; then
  for cand in python3.13 python3.12 python3.11 python3; do
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
      py="$cand"; break
    fi
  done
fi
[ -n "$py" ] || { echo "ftc-hw needs Python >= 3.11 on PATH (or set FTC_PYTHON)" >&2; exit 1; }
if [ ! -x "$venv/bin/python" ]; then
  echo "[bootstrap] creating $venv with $py" >&2
  "$py" -m venv "$venv"
fi
stamp="$venv/.ftc-installed"
want="$(cat "$root/pyproject.toml" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "[bootstrap] installing ftc-hw, its ROS 2 extra and its test dependencies into .venv" >&2
  # uv installs the same pins in seconds where pip takes about a minute (CI's 15-minute budget); pip
  # installs them if uv cannot be had. Byte-compiled at install, as pip does: with PYTHONDONTWRITEBYTECODE
  # set (CI sets it) every emulator and CLI process would otherwise compile numpy, MuJoCo's bindings and
  # the rest from source at each start
  if ! { "$venv/bin/python" -m pip install --quiet --disable-pip-version-check uv >&2 \
         && "$venv/bin/python" -m uv pip install --quiet --compile-bytecode --python "$venv/bin/python" -e "$root[test,ros]" >&2; }; then
    echo "[bootstrap] uv unavailable or failed: installing with pip" >&2
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -e "$root[test,ros]" >&2
  fi
  echo "$want" > "$stamp"
  rm -f "$venv/.ftc-warmed"  # numba itself may have changed
fi
# The vendor meshes the built-in scenes name (the simulated world's true shell): fetched once, ~30 MB.
if ! "$venv/bin/ftc" scenes --fetch-meshes >/dev/null; then
  echo "[bootstrap] warning: vendor meshes not fetched; simulated worlds use primitive shells (ftc scenes --fetch-meshes)" >&2
fi
warmed="$venv/.ftc-warmed"
sources=("$root/ftc_hw" "$root/sim_devices" "$root/calibration" "$root/devices")
if [ ! -f "$warmed" ] || [ -n "$(find "${sources[@]}" -name '*.py' -newer "$warmed" -print -quit)" ] \
   || { [ -z "${NUMBA_CACHE_DIR:-}" ] && ! compgen -G "$root/ftc_hw/solver/__pycache__/*.nbi" >/dev/null; }; then
  echo "[bootstrap] compiling the numba kernels into numba's cache (ftc warm: once, minutes; after an edit, what changed)" >&2
  touch "$warmed.new"  # a file edited during the warm-up is newer than the stamp
  if "$venv/bin/ftc" warm; then
    mv "$warmed.new" "$warmed"
  else
    rm -f "$warmed.new"
    echo "[bootstrap] warning: ftc warm failed; the first run compiles its kernels itself (slow start)" >&2
  fi
fi
