#!/usr/bin/env bash
# Builds the firmware for one board and horizon, runs it in QEMU and decodes its log.
#
#   firmware-example/run.sh BOARD N OUT [sil|build]
#
# BOARD: an386 (Cortex-M4F), an500 (Cortex-M7) or an505 (Cortex-M33); N: 20 or 50.
# OUT gets the decoded log (defmt-print, one line per message). The exit status is the
# firmware's: 0 only if both scenarios met every check (src/main.rs), 2 for bad arguments.
# With `sil`, the vehicle computer in the loop (src/sil.rs, src/sil_node.rs) runs instead, driven over its
# UART by sil_check.py (python-can's slcan interface, cantools): 0 only if both sides'
# checks passed. That needs Python with python-can, pyserial and cantools.
# With `build`, it only builds: OUT is a directory that gets both images (firmware-example
# and sil). FW_IMAGES=DIR runs the images in DIR instead of building (DIR as `build` wrote
# it for the same BOARD and N), so that the builds can go one after another while the
# runs, one core each, go side by side (.ci/run).
# Needs qemu-system-arm and defmt-print (`cargo install defmt-print`). FW_SECOC_KEY, if
# set, is the node's key (build.rs). `-icount shift=3,sleep=off` makes the run
# deterministic: one instruction is 8 ns of virtual time.
set -euo pipefail

usage() { echo "usage: $0 an386|an500|an505 20|50 OUT [sil|build]" >&2; exit 2; }
[ $# = 3 ] || { [ $# = 4 ] && { [ "$4" = sil ] || [ "$4" = build ]; }; } || usage
board=$1 n=$2 out=$3 program=${4:-scripted}
case "$board" in
  an386) features="" target=thumbv7em-none-eabihf cpu=cortex-m4 ;;
  an500) features="an500" target=thumbv7em-none-eabihf cpu=cortex-m7 ;;
  an505) features="an505" target=thumbv8m.main-none-eabihf cpu=cortex-m33 ;;
  *) usage ;;
esac
case "$n" in
  20) ;;
  50) features="$features n50" ;;
  *) usage ;;
esac
# Refuse an output we could not write before spending a build on it.
if [ "$program" = build ]; then out_dir=$out; else out_dir=$(dirname -- "$out"); fi
[ -d "$out_dir" ] && [ -w "$out_dir" ] || { echo "$0: cannot write to $out_dir" >&2; exit 2; }

cd "$(dirname -- "$0")"
if [ -n "${FW_IMAGES:-}" ]; then
  [ "$program" != build ] || usage
  images=$FW_IMAGES
  for image in firmware-example sil; do
    [ -f "$images/$image" ] || { echo "$0: no $image in FW_IMAGES=$images" >&2; exit 2; }
  done
else
  # Cargo says where it builds (CARGO_TARGET_DIR may move it).
  target_dir=$(cargo metadata --format-version 1 --no-deps \
    | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')
  # shellcheck disable=SC2086
  cargo build --release --target "$target" ${features:+--features "${features# }"}
  images="$target_dir/$target/release"
fi
if [ "$program" = build ]; then
  cp "$images/firmware-example" "$images/sil" "$out/"
  exit 0
fi
if [ "$program" = sil ]; then
  exec python3 sil_check.py "$images/sil" "$board" "$out"
fi
elf="$images/firmware-example"
raw=$(mktemp)
trap 'rm -f "$raw"' EXIT
status=0
timeout 600 qemu-system-arm -machine "mps2-$board" -cpu "$cpu" -nographic \
  -semihosting-config enable=on,target=native -icount shift=3,sleep=off \
  -kernel "$elf" > "$raw" || status=$?
defmt-print -e "$elf" --log-format '{s}' < "$raw" > "$out"
exit "$status"
