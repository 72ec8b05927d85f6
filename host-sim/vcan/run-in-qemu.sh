#!/usr/bin/env bash
# The real-vcan test (issue 6): boots Debian's own kernel under qemu-system-x86_64 (TCG;
# this machine's kernel has no CAN), loads its can, can-raw, can-dev and vcan modules,
# and runs `host-sim run SCENARIO --bus vcan0` there — a task and a SocketCAN socket per
# vehicle — with `candump -l vcan0` logging every frame. Then, on the host, checks the
# summary (no collision, no violation, every frame accepted) and decodes the candump log
# with cantools and the DBC against the vehicles' trace (check_vcan_run.py).
#
# Usage: host-sim/vcan/run-in-qemu.sh [SCENARIO.toml] [OUT_DIR]
# Needs: qemu-system-x86_64, apt-get (Debian's archive), cargo with the
# x86_64-unknown-linux-musl target, python3 with cantools (.ci/run installs all of them).
# The kernel, busybox-static and can-utils come from Debian's packages (apt-get download);
# nothing is installed on this machine by this script.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
scenario="$(realpath "${1:-$root/scenarios/multilane.toml}")"
out="$(mkdir -p "${2:-$root/target/vcan-qemu}" && cd "${2:-$root/target/vcan-qemu}" && pwd)"
debs="$out/debs"
mkdir -p "$debs"

for tool in qemu-system-x86_64 apt-get dpkg-deb python3 cargo; do
  command -v "$tool" >/dev/null || { echo "run-in-qemu: $tool is missing" >&2; exit 2; }
done

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

echo "== host-sim, statically linked (musl)"
(cd "$root" && cargo build --release -q -p host-sim --target x86_64-unknown-linux-musl)
hostsim="$root/target/x86_64-unknown-linux-musl/release/host-sim"
if file "$hostsim" 2>/dev/null | grep -q 'dynamically linked'; then
  echo "run-in-qemu: $hostsim is not static" >&2
  exit 1
fi

echo "== initramfs: busybox, candump (+ its libc), the 4 modules, host-sim, the scenario"
r="$out/rootfs"
mkdir -p "$r"/{bin,proc,sys,dev,work,lib/modules,lib64,lib/x86_64-linux-gnu}
cp "$out/pkg/bin/busybox" "$r/bin/busybox"
cp "$out/pkg/usr/bin/candump" "$r/bin/candump"
# candump is linked against glibc: the loader and libc of this (same-release) system.
for lib in $(ldd "$out/pkg/usr/bin/candump" | grep -oE '/[^ ]+\.so[^ ]*'); do
  mkdir -p "$r$(dirname "$lib")"
  cp -L "$lib" "$r$lib"
done
mods="$out/pkg/lib/modules/$kver/kernel"
cp "$mods/net/can/can.ko" "$mods/net/can/can-raw.ko" \
   "$mods/drivers/net/can/dev/can-dev.ko" "$mods/drivers/net/can/vcan.ko" "$r/lib/modules/"
cp "$hostsim" "$r/bin/host-sim"
cp "$here/init" "$r/init"
chmod +x "$r/init"
cp "$scenario" "$r/work/scenario.toml"
echo "${HOST_SIM_ARGS:-}" > "$r/work/args"
(cd "$r" && find . | "$r/bin/busybox" cpio -o -H newc 2>/dev/null | gzip -1) > "$out/initramfs.gz"

echo "== boot linux $kver under qemu-system-x86_64 (TCG)"
start=$(date +%s)
timeout 900 qemu-system-x86_64 -accel tcg -cpu max -smp 2 -m 512 -nographic -no-reboot \
  -kernel "$kernel" -initrd "$out/initramfs.gz" \
  -append "console=ttyS0 panic=-1 quiet loglevel=3" > "$out/console.log" 2>&1 || true
tr -d '\r' < "$out/console.log" > "$out/console.txt"
echo "VM ran $(( $(date +%s) - start )) s"

section() { # name → stdout
  awk -v b="=== BEGIN $1" -v e="=== END $1" '$0==e{p=0} p{print} $0==b{p=1}' "$out/console.txt"
}
status="$(sed -n 's/^=== VCAN-TEST STATUS //p' "$out/console.txt" | tail -1)"
grep '^=== vcan0' "$out/console.txt" || true
if [ -z "$status" ]; then
  echo "run-in-qemu: the VM did not finish; console:" >&2
  tail -40 "$out/console.txt" >&2
  exit 1
fi
section summary.json > "$out/summary.json"
log_name="$(sed -n 's/^=== BEGIN \(candump-.*\.log\)$/\1/p' "$out/console.txt" | head -1)"
[ -n "$log_name" ] || { echo "run-in-qemu: no candump log in the console output" >&2; exit 1; }
section "$log_name" | base64 -d | gunzip > "$out/candump.log"
section trace.csv | base64 -d | gunzip > "$out/trace.csv"
echo "host-sim exit status in the VM: $status"
cat "$out/summary.json"
echo
python3 "$here/check_vcan_run.py" "$root/can-gateway/can-gateway.dbc" \
  "$out/summary.json" "$out/candump.log" "$out/trace.csv" "$status"
