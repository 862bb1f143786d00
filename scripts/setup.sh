#!/usr/bin/env bash
# Installs the system packages handeye needs to build and run, and only those that are missing.
# Safe to run repeatedly; needs root (or sudo) only when something is actually missing.
#
#   mesa-vulkan-drivers + libvulkan1  software Vulkan (lavapipe) for the simulator's renderer
#                                     on machines without a GPU; skipped when a Vulkan ICD exists.
#   gcc + libc6-dev                   the C linker Rust links with; only if `cc` is missing
#                                     (a bare rustup install does not bring one).
#   pkg-config                        how the gstreamer crates find the GStreamer libraries.
#   libgstreamer1.0-dev +             GStreamer's headers and .pc files, to build `handeye camera`
#   libgstreamer-plugins-base1.0-dev  (the default cargo feature `camera`; appsink, video).
#   gstreamer1.0-plugins-base         videoconvert, videoscale, videotestsrc, decodebin: what
#                                     every `handeye camera` pipeline ends with, and test sources.
#   gstreamer1.0-plugins-good         v4l2src (USB cameras), mp4 (de)muxing, pngdec, multifilesrc.
#   gstreamer1.0-plugins-ugly         x264enc: the tests make an H.264 video from real frames.
#   gstreamer1.0-libav                avdec_h264: decoding H.264 files and cameras.
#   util-linux                        setpriv: tests/permissions.rs runs an intruder as `nobody`
#                                     (Essential in Debian, so only a stripped image lacks it).
#   stress-ng                         `make stress` loads every core while the closed loop runs.
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
command -v setpriv >/dev/null 2>&1 || need+=(util-linux)
command -v stress-ng >/dev/null 2>&1 || need+=(stress-ng)
# Debian packages by name: installed ones are skipped.
have_deb() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q 'ok installed'; }
for p in pkg-config libgstreamer1.0-dev libgstreamer-plugins-base1.0-dev gstreamer1.0-plugins-base \
         gstreamer1.0-plugins-good gstreamer1.0-plugins-ugly gstreamer1.0-libav; do
    have_deb "$p" || need+=("$p")
done

if [ ! -w /dev/shm ]; then
    echo "setup: warning: /dev/shm is missing or not writable; handeye's shared memory needs it" >&2
fi

if [ ${#need[@]} -eq 0 ]; then
    echo "setup: system packages present (Vulkan loader and ICD, C linker, GStreamer and its plugins)"
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
