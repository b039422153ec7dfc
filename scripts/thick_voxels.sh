#!/usr/bin/env bash
# "Optically thick voxels" (docs/accuracy.md): two clouds with medium.sigma_t swept, every
# deterministic method against `reference` (256 paths per pixel, --stderr), 4×4 block means over
# the cloud, and the median optical depth of the voxels light enters through where the renderer's
# warning gives it (above 2.5, src/medium/skin.rs). The procedural cloud on a 40×32×24 grid of
# 25-m voxels (64×48 pixels) and the Disney cloud (tests/data/clouds/wdas.toml: 13.3-m voxels,
# 48×36 pixels). A markdown table on stdout.
#
#   scripts/thick_voxels.sh [OUT_DIR]      (default thick-out; scenes and EXRs land there)
#
# Environment: CLOUDGI the binary (default target/release/cloudgi). References already in OUT_DIR
# are reused.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-thick-out}
bin=${CLOUDGI:-$root/target/release/cloudgi}
command -v jq >/dev/null || { echo "scripts/thick_voxels.sh: needs jq" >&2; exit 2; }
[ -x "$bin" ] || { echo "scripts/thick_voxels.sh: no binary $bin (cargo build --release, or set CLOUDGI)" >&2; exit 2; }
mkdir -p "$out"
cells() { jq -r '"\(.block_mean_relative_error * 1000 | round / 10) / \(.block_bias * 1000 | round / 10) %"'; }

# One row: NAME (file stem), LABEL, σt·h (optical depth of a density-1 voxel), width, height, and
# optionally the NAME whose reference it shares (a refined cloud is the same density field).
row() {
    local name=$1 label=$2 tau=$3 w=$4 h=$5 line noise entry
    local scene="$out/$name.toml" ref="$out/${6:-$name}-reference.exr"
    [ -f "$ref" ] || "$bin" -q --threads 1 render "$scene" --method reference --spp 256 --stderr \
        --width "$w" --height "$h" -o "$ref" 2>/dev/null
    line="| $label | $tau"
    for m in diffusion full transport; do
        if "$bin" -q --threads 1 render "$scene" --method "$m" --width "$w" --height "$h" \
            -o "$out/$name-$m.exr" 2>"$out/$name-$m.log"; then
            line="$line | $("$bin" compare "$out/$name-$m.exr" "$ref" | cells)"
        else
            line="$line | refused"
        fi
    done
    noise=$("$bin" compare "$ref" "$ref" | jq -r '.reference_block_noise * 1000 | round / 10')
    entry=$(grep -o 'through voxels [0-9.]* optical' "$out/$name-transport.log" | awk '{print $3}' || true)
    echo "$line | $noise % | ${entry:-≤ 2.5} |"
}

echo "| cloud, medium.sigma_t | σt·h | diffusion | full | transport | ref. noise | entry voxels (warning) |"
echo "|---|---|---|---|---|---|---|"
for st in 0.05 0.1 0.2 0.3 0.5 1.0 2.0 5.0; do
    sed -e 's/^resolution = \[100, 80, 60\]/resolution = [40, 32, 24]/' \
        -e 's/^voxel_size = 10.0 /voxel_size = 25.0 /' \
        -e "s/^sigma_t = 0.05 /sigma_t = $st /" "$root/examples/default.toml" > "$out/procedural-$st.toml"
    row "procedural-$st" "procedural, $st" "$(echo "$st * 25" | bc -l | sed 's/0*$//; s/\.$//')" 64 48
done
# The thick rows again with the voxels refined (medium.refine: the same field, k³ the voxels).
for st_k in 0.3:3 0.5:3 1.0:3 2.0:3 2.0:5 5.0:5; do
    st=${st_k%:*} k=${st_k#*:}
    sed -e "s/^sigma_t = $st /sigma_t = $st\nrefine = $k /" "$out/procedural-$st.toml" > "$out/procedural-$st-r$k.toml"
    row "procedural-$st-r$k" "procedural, $st, refine $k" "$(echo "$st * 25 / $k" | bc -l | xargs printf '%.3g')" 64 48 "procedural-$st"
done
for st in 0.08 0.8 3.0; do
    sed -e "s#^grid = \"#grid = \"$root/tests/data/clouds/#" -e "s/^sigma_t = 0.08/sigma_t = $st/" \
        "$root/tests/data/clouds/wdas.toml" > "$out/disney-$st.toml"
    row "disney-$st" "Disney, $st" "$(echo "$st * 40 / 3" | bc -l | xargs printf '%.2f')" 48 36
done
