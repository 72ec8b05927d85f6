#!/usr/bin/env bash
# The real-vcan test: boots Debian's own kernel under qemu-system-x86_64 (TCG;
# this machine's kernel has no CAN), loads its can, can-raw, can-dev and vcan modules,
# and runs `host-sim run SCENARIO --bus vcan0` there for each scenario — a task and a
# SocketCAN socket per vehicle (and one for an intersection's manager) — with candump
# logging every frame of each run. Then, on the host, checks each summary (no collision,
# no violation, every frame accepted, the goals met) and decodes each candump log with
# cantools and the DBC (check_vcan_run.py): against the vehicles' trace for a road
# scenario, against the summary's message counts for an intersection.
#
# Usage: host-sim/vcan/run-in-qemu.sh [SCENARIO.toml ...] [--can-fd SCENARIO.toml ...]
#   (default: multilane.toml). Scenarios after --can-fd run with `--can-fd`: every
#   message in one CAN FD frame (vcan0 has MTU 72, so both kinds travel on it).
# Then, on vcan0 too, `host-sim experiment attacks --bus vcan0 $VCAN_ATTACKS` (default:
# the forged grant at the intersection, authenticated, on CAN FD, no clean run beside it);
# its JSON must show no forgery accepted, no unsafe event and every vehicle done.
# VCAN_ATTACKS="" skips it.
# VCAN_HOST_SIM=PATH: run that release build of host-sim instead of building one.
# Results go to $VCAN_OUT (default: vcan-qemu in cargo's target directory).
# Needs: qemu-system-x86_64, apt-get (Debian's archive), cargo, ldd, python3 with
# cantools (.ci/run installs all of them).
# The kernel, busybox-static and can-utils come from Debian's packages (apt-get download);
# nothing is installed on this machine by this script.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
scenarios=()
fd=() # per scenario: "--can-fd" or ""
on_fd=""
for sc in "${@:-$root/scenarios/multilane.toml}"; do
  if [ "$sc" = "--can-fd" ]; then
    on_fd="--can-fd"
    continue
  fi
  [ -f "$sc" ] || { echo "run-in-qemu: no scenario $sc" >&2; exit 2; }
  scenarios+=("$(realpath "$sc")")
  fd+=("$on_fd")
done
[ "${#scenarios[@]}" -gt 0 ] || { echo "run-in-qemu: no scenario after --can-fd" >&2; exit 2; }
for tool in qemu-system-x86_64 apt-get dpkg-deb ldd python3 cargo; do
  command -v "$tool" >/dev/null || { echo "run-in-qemu: $tool is missing" >&2; exit 2; }
done
# Cargo says where it builds (CARGO_TARGET_DIR may move it).
target="$(cd "$root" && cargo metadata --format-version 1 --no-deps \
  | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
out="$(mkdir -p "${VCAN_OUT:-$target/vcan-qemu}" && cd "${VCAN_OUT:-$target/vcan-qemu}" && pwd)"
debs="$out/debs"
mkdir -p "$debs"

echo "== Debian packages: the kernel linux-image-amd64 depends on, busybox-static, can-utils"
kernel_of() { apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/ {print $2; exit}'; }
fetch() { # the kernel linux-image-amd64 points to (-unsigned: the same image), busybox, can-utils
  kernel_pkg="$(kernel_of)-unsigned"
  [ "$kernel_pkg" != "-unsigned" ] || return 1
  (
    cd "$debs"
    for p in "$kernel_pkg" busybox-static can-utils; do
      ls "${p}"_*.deb >/dev/null 2>&1 || apt-get download "$p" >/dev/null 2>&1 || exit 1
    done
  )
}
# Package lists missing or stale (a version gone from the archive): refresh once.
fetch || { apt-get update -qq && fetch; } || { echo "run-in-qemu: cannot download the packages" >&2; exit 1; }
kver="${kernel_pkg#linux-image-}"
kver="${kver%-unsigned}"
rm -rf "$out/pkg" "$out/rootfs"
mkdir -p "$out/pkg"
for d in "$debs"/*.deb; do dpkg-deb -x "$d" "$out/pkg"; done
kernel="$out/pkg/boot/vmlinuz-$kver"
[ -f "$kernel" ] || { echo "run-in-qemu: no kernel $kernel" >&2; exit 1; }

echo "== host-sim (release, the host's build) and the shared libraries it and candump link"
# The host's own release build, with the loader and libraries `ldd` names copied beside
# it (this Debian and the VM's packages are one release): no second build of host-sim for
# another target (a static musl build cost CI three minutes of compiling beside the
# tests; in the VM both run the multi-lane road alike).
# VCAN_HOST_SIM names a build already made (CI's): then no cargo runs here, so the VM
# never waits for the build directory's lock while a test build beside it holds it.
if [ -n "${VCAN_HOST_SIM:-}" ]; then
  hostsim="$VCAN_HOST_SIM"
  [ -x "$hostsim" ] || { echo "run-in-qemu: VCAN_HOST_SIM=$hostsim is not an executable" >&2; exit 2; }
else
  (cd "$root" && cargo build --release -q -p host-sim)
  hostsim="$target/release/host-sim"
fi
echo "== initramfs: busybox, candump and host-sim (+ their glibc), the 4 modules, the scenarios"
r="$out/rootfs"
mkdir -p "$r"/{bin,proc,sys,dev,work/scenarios,lib/modules,lib64,lib/x86_64-linux-gnu}
cp "$out/pkg/bin/busybox" "$r/bin/busybox"
cp "$out/pkg/usr/bin/candump" "$r/bin/candump"
# Both are linked against glibc: the loader and libraries of this (same-release) system.
for lib in $(ldd "$out/pkg/usr/bin/candump" "$hostsim" | grep -oE '/[^ ]+\.so[^ ]*' | sort -u); do
  mkdir -p "$r$(dirname "$lib")"
  cp -L "$lib" "$r$lib"
done
mods="$out/pkg/lib/modules/$kver/kernel"
cp "$mods/net/can/can.ko" "$mods/net/can/can-raw.ko" \
   "$mods/drivers/net/can/dev/can-dev.ko" "$mods/drivers/net/can/vcan.ko" "$r/lib/modules/"
cp "$hostsim" "$r/bin/host-sim"
cp "$here/init" "$r/init"
chmod +x "$r/init"
i=0
for sc in "${scenarios[@]}"; do # numbered: run in the order given
  i=$((i + 1))
  cp "$sc" "$r/work/scenarios/$i-$(basename "$sc")"
  echo "${fd[$((i - 1))]}" > "$r/work/scenarios/$i-$(basename "$sc" .toml).args"
done
echo "${HOST_SIM_ARGS:-}" > "$r/work/args"
echo "${VCAN_ATTACKS-"--only forged-grant --world intersection --can-fd --no-baseline"}" > "$r/work/attacks"
(cd "$r" && find . | "$r/bin/busybox" cpio -o -H newc 2>/dev/null | gzip -1) > "$out/initramfs.gz"

echo "== boot linux $kver under qemu-system-x86_64 (TCG)"
start=$(date +%s)
timeout 1800 qemu-system-x86_64 -accel tcg -cpu max -smp 2 -m 512 -nographic -no-reboot \
  -kernel "$kernel" -initrd "$out/initramfs.gz" \
  -append "console=ttyS0 panic=-1 quiet loglevel=3" > "$out/console.log" 2>&1 || true
tr -d '\r' < "$out/console.log" > "$out/console.txt"
echo "VM ran $(( $(date +%s) - start )) s"

section() { # name → stdout
  awk -v b="=== BEGIN $1" -v e="=== END $1" '$0==e{p=0} p{print} $0==b{p=1}' "$out/console.txt"
}
grep '^=== vcan0' "$out/console.txt" || true
if ! grep -q '^=== VCAN-TEST STATUS done$' "$out/console.txt"; then
  echo "run-in-qemu: the VM did not finish; console:" >&2
  tail -40 "$out/console.txt" >&2
  exit 1
fi
failed=0
i=0
for sc in "${scenarios[@]}"; do
  i=$((i + 1))
  name="$i-$(basename "$sc" .toml)"
  d="$out/$name"
  rm -rf "$d"
  mkdir -p "$d"
  status="$(sed -n "s/^=== SCENARIO $name STATUS //p" "$out/console.txt" | tail -1)"
  echo "== $name: host-sim exit status in the VM: ${status:-none}"
  grep "^=== softnet after $name:" "$out/console.txt" || true
  section "$name/summary.json" > "$d/summary.json"
  section "$name/candump.log" | base64 -d | gunzip > "$d/candump.log" || true
  trace="-"
  if grep -q "^=== BEGIN $name/trace.csv\$" "$out/console.txt"; then
    section "$name/trace.csv" | base64 -d | gunzip > "$d/trace.csv"
    trace="$d/trace.csv"
  fi
  cat "$d/summary.json"
  echo
  python3 "$here/check_vcan_run.py" "$root/can-gateway/can-gateway.dbc" \
    "$d/summary.json" "$d/candump.log" "$trace" "${status:-none}" || failed=1
done
if [ -n "${VCAN_ATTACKS-x}" ]; then
  status="$(sed -n 's/^=== ATTACKS STATUS //p' "$out/console.txt" | tail -1)"
  echo "== experiment attacks on vcan0: host-sim exit status in the VM: ${status:-none}"
  section attacks.json > "$out/attacks.json"
  cat "$out/attacks.json"
  echo
  python3 "$here/check_attacks.py" "$out/attacks.json" "${status:-none}" || failed=1
fi
exit "$failed"
