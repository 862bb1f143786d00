#!/usr/bin/env bash
# Installs the system packages handeye needs at run time, and only those that are missing.
# Safe to run repeatedly; needs root (or sudo) only when something is actually missing.
#
#   mesa-vulkan-drivers + libvulkan1  software Vulkan (lavapipe) for the simulator's renderer
#                                     on machines without a GPU; skipped when a Vulkan ICD exists.
#   gcc + libc6-dev                   the C linker Rust links with; only if `cc` is missing
#                                     (a bare rustup install does not bring one).
#
# iceoryx2 needs nothing but a writable /dev/shm (and /tmp); rapier, nalgebra and glam need
# nothing.
set -euo pipefail

need=()
have_icd=false
for d in /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/share/vulkan/icd.d; do
    if compgen -G "$d/*.json" >/dev/null 2>&1; then have_icd=true; fi
done
loader=false
if ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1'; then loader=true; fi
$loader || need+=(libvulkan1)
$have_icd || need+=(mesa-vulkan-drivers)
command -v cc >/dev/null 2>&1 || need+=(gcc libc6-dev)

if [ ! -w /dev/shm ]; then
    echo "setup: warning: /dev/shm is missing or not writable; handeye's shared memory needs it" >&2
fi

if [ ${#need[@]} -eq 0 ]; then
    echo "setup: system packages present (Vulkan loader and ICD, C linker)"
    exit 0
fi

echo "setup: installing ${need[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
        echo "setup: need root to install: ${need[*]} (run: apt-get install -y ${need[*]})" >&2
        exit 1
    fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${need[@]}"
echo "setup: done"
