#!/usr/bin/env bash
# "Albedo below 1" (docs/accuracy.md): examples/eval/glare/sun035.toml at 64×48 with the medium's
# albedo and g swept, `transport`, `full` and `diffusion` against `reference` (2048 paths per pixel,
# seed 1, --stderr), 4×4 block means over the cloud. A markdown table on stdout: block error /
# bias / the reference's block noise, in %.
#
#   scripts/albedo_sweep.sh [OUT_DIR]      (default albedo-out; scenes and EXRs land there)
#
# Environment: CLOUDGI the binary (default target/release/cloudgi), ALBEDOS and GS the values
# swept (default 0.999 0.99 0.97 0.95 0.9 0.8 0.65 0.5 0.3, and 0.9 0.0). References already in
# OUT_DIR are reused (about 30 CPU-s each).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-albedo-out}
bin=${CLOUDGI:-$root/target/release/cloudgi}
albedos=${ALBEDOS:-0.999 0.99 0.97 0.95 0.9 0.8 0.65 0.5 0.3}
gs=${GS:-0.9 0.0}
command -v jq >/dev/null || { echo "scripts/albedo_sweep.sh: needs jq" >&2; exit 2; }
[ -x "$bin" ] || { echo "scripts/albedo_sweep.sh: no binary $bin (cargo build --release, or set CLOUDGI)" >&2; exit 2; }
mkdir -p "$out"
cells() { jq -r '"\(.block_mean_relative_error * 1000 | round / 10) / \(.block_bias * 1000 | round / 10)"'; }

echo "| albedo | g | transport | full | diffusion | ref. noise |"
echo "|---|---|---|---|---|---|"
for g in $gs; do
    for a in $albedos; do
        name="a${a}g${g}"
        scene="$out/$name.toml"
        sed -e "s/^albedo = .*/albedo = [$a, $a, $a]/" -e "s/^g = .*/g = $g/" \
            -e "s/^width = .*/width = 64/" -e "s/^height = .*/height = 48/" \
            "$root/examples/eval/glare/sun035.toml" >"$scene"
        ref="$out/$name-reference.exr"
        [ -f "$ref" ] || "$bin" -q render "$scene" --method reference --spp 2048 --stderr --seed 1 -o "$ref" 2>/dev/null
        line="| $a | $g"
        for m in transport full diffusion; do
            "$bin" -q render "$scene" --method "$m" -o "$out/$name-$m.exr" 2>/dev/null
            line="$line | $("$bin" compare "$out/$name-$m.exr" "$ref" | cells)"
        done
        noise=$("$bin" compare "$ref" "$ref" | jq -r '.reference_block_noise * 1000 | round / 10')
        echo "$line | $noise |"
    done
done
