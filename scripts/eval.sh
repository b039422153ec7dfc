#!/usr/bin/env bash
# "What the eye sees" (docs/accuracy.md): every scene of examples/eval/glare rendered with
# `reference` (seed 1 long, with --stderr; seed 2 shorter, to check the noise estimate) and with
# each method, scored by `cloudgi compare` as 4×4 block means: over the cloud (the reference's
# transmittance < 0.99) and over the whole frame (sky and ground too). A markdown table on stdout.
#
#   scripts/eval.sh [OUT_DIR]      (default eval-out; EXRs, PNGs and diff PNGs land there)
#
# Environment: CLOUDGI the binary (default target/release/cloudgi), COMPARE the binary that scores
# (default CLOUDGI; to score an older build's renders), METHODS (default
# "transport full"), SCENES (default every examples/eval/glare/*.toml), REF_SPP (a scene's
# `# reference_spp = N` line, else 6144), REF2_SPP (a third of it), REFS_ONLY=1 (render the missing
# references and stop). References already in OUT_DIR are reused: delete them after changing a scene
# or `reference`.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-eval-out}
bin=${CLOUDGI:-$root/target/release/cloudgi}
cmp=${COMPARE:-$bin}
methods=${METHODS:-transport full}
scenes=${SCENES:-$(ls "$root"/examples/eval/glare/*.toml)}
for tool in jq /usr/bin/time; do
    command -v "$tool" >/dev/null || { echo "scripts/eval.sh: needs $tool" >&2; exit 2; }
done
[ -x "$bin" ] || { echo "scripts/eval.sh: no binary $bin (cargo build --release, or set CLOUDGI)" >&2; exit 2; }
mkdir -p "$out"

# "error bias" of a compare line, in per cent with one decimal ("–" where absent).
pct() { jq -r '[.block_mean_relative_error, .block_bias] | map(if . == null then "–" else (. * 1000 | round / 10 | tostring) end) | join(" / ")'; }

header="| scene | ref. noise (stderr) | seed 2 vs 1 |"
rule="|---|---|---|"
for m in $methods; do
    header+=" $m: cloud | $m: frame | $m CPU s |"
    rule+="---|---|---|"
done
[ -n "${REFS_ONLY:-}" ] || { echo "$header"; echo "$rule"; }
for scene in $scenes; do
    name=$(basename "$scene" .toml)
    ref="$out/$name-reference.exr"
    ref2="$out/$name-reference-seed2.exr"
    scene_spp=$(sed -n 's/^# reference_spp = \([0-9]*\).*/\1/p' "$scene")
    ref_spp=${REF_SPP:-${scene_spp:-6144}}
    ref2_spp=${REF2_SPP:-$((ref_spp / 3))}
    [ -f "$ref" ] || nice "$bin" render "$scene" --method reference --spp "$ref_spp" --seed 1 --stderr -o "$ref" -q
    [ -f "$ref2" ] || nice "$bin" render "$scene" --method reference --spp "$ref2_spp" --seed 2 -o "$ref2" -q
    [ -z "${REFS_ONLY:-}" ] || continue
    noise=$("$cmp" compare "$ref" "$ref" | jq -r '.reference_block_noise * 1000 | round / 10 | tostring')
    seeds=$("$cmp" compare "$ref2" "$ref" | pct)
    row="| $name | $noise % | $seeds % |"
    for m in $methods; do
        img="$out/$name-$m.exr"
        /usr/bin/time -f "%U %S" -o "$out/$name-$m.time" nice "$bin" render "$scene" --method "$m" -o "$img" -q
        cpu=$(awk '{printf "%.1f", $1 + $2}' "$out/$name-$m.time")
        cloud=$("$cmp" compare "$img" "$ref" --diff "$out/$name-$m-diff.png" | pct)
        frame=$("$cmp" compare "$img" "$ref" --all-pixels | pct)
        row+=" $cloud % | $frame % | $cpu |"
    done
    echo "$row"
done
