#!/usr/bin/env bash
# CPU-seconds per compile unit: use as RUSTC_WRAPPER; appends one line per rustc call to the file
# $RUSTC_TIME_LOG: user and system CPU-s, crate name, crate type, build or check, opt-level,
# "test" for a test harness. docs/performance.md ("Build and test time", "Reproduce").
#   RUSTC_WRAPPER=$PWD/scripts/rustc_time.sh RUSTC_TIME_LOG=/tmp/units.log cargo test --release
#   awk '{s += $1 + $2} END {print s}' /tmp/units.log
set -euo pipefail
rustc=$1
shift
name=unknown kind="" emit="" opt="" test="" prev=""
for a in "$@"; do
  case "$prev" in --crate-name) name=$a ;; --crate-type) kind=$a ;; --emit) emit=$a ;; esac
  case "$a" in --emit=*) emit=${a#--emit=} ;; opt-level=*) opt=$a ;; --test) test=test ;; esac
  prev=$a
done
case "$emit" in *link*) mode=build ;; "") mode=query ;; *) mode=check ;; esac
exec /usr/bin/time -a -o "${RUSTC_TIME_LOG:?set RUSTC_TIME_LOG to the log file}" -f "%U %S $name $kind $mode $opt $test" "$rustc" "$@"
