#!/usr/bin/env bash
# Regenerates the gallery (docs/gallery: the pictures of the site and the README): each image is one `rcp`
# command, the same one its page shows.
set -euo pipefail
cd "$(dirname "$0")/.."
out=docs/gallery
mkdir -p "$out"
rcp -q render default --out "$out/default.jpg"
rcp -q render default --out "$out/default-plain.jpg" --iterations 1
rcp -q render sea --out "$out/sea.jpg" --time 2.5
rcp -q render sky --out "$out/sky.jpg" --lambda-p 24
rcp -q render default --out "$out/default-normal.jpg" --mapping normal --lambda-p 14 --noise 0.35 --spp 4
rcp -q render default --out "$out/default-eye.jpg" --lambda-e 0.08 --lambda-p 6
# a painting per object and material, toon shading and outlines (scenes/figures.toml); the cubist eye mapping
rcp -q render figures --out "$out/figures.jpg"
rcp -q render figures --out "$out/figures-plain.jpg" --iterations 1
rcp -q render figures --out "$out/figures-cubist.jpg" --eye-mapping cubist --lambda-e 0.2 --lambda-p 0
rcp -q render default --out "$out/default-sharp-trees.jpg" --paint docs/sharp-trees.json
# the paper's figure 2: iterations 1 to 6, side by side
its=$(mktemp -d)
rcp -q render default --out "$its/final.png" --width 320 --height 180 --save-iterations "$its"
python - "$its" "$out/iterations.jpg" <<'PY'
import sys
from PIL import Image
frames = [Image.open(f"{sys.argv[1]}/iteration_{k}.png") for k in range(1, 7)]
w, h = frames[0].size
strip = Image.new("RGB", (3 * w, 2 * h))
for k, frame in enumerate(frames):
    strip.paste(frame, ((k % 3) * w, (k // 3) * h))
strip.save(sys.argv[2], quality=88)
PY
rm -rf "$its"
# the styles (rcp_server/settings/styles.py), each on the default scene
for style in smudge focus fractured cross-hatching layered; do
  rcp -q render default --out "$out/style-$style.jpg" --style "$style" --quality 85
done
# all around: 360 x 180 panoramas (an eye's image twice as wide as high), and a stereo pair
rcp -q render default --out "$out/360-village.jpg" --projection equirect --width 1024 --height 512
rcp -q render sky --out "$out/360-sky.jpg" --projection equirect --width 1024 --height 512 --lambda-p 24
rcp -q render default --out "$out/stereo.jpg" --stereo side-by-side --width 480 --height 270
