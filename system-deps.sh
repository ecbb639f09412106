#!/bin/sh
# System libraries that pip cannot install, added with apt-get (Debian, Ubuntu) when missing;
# a no-op when they are present. Needs root (or password-less sudo); otherwise it says what to
# install and leaves the rest to the commands that follow it.
#
# - libLLVM 19 or newer: Dr.Jit's CPU backend compiles Mitsuba's kernels with the system's
#   libLLVM (the newest it finds). Debian 12's LLVM 14-16 cannot compile the rendered mode's
#   BSDFs, and on AVX-512 CPUs (seen on an AMD EPYC Zen 4) they abort the process on any scan
#   (rangesim refuses them with a one-line message instead).
# - libusb-1.0: Open3D (an optional peer in the benchmarks and I/O checks) loads it at import.
set -u

have_llvm19() {
    for v in 19 20 21 22 23 24 25; do
        for f in /usr/lib/*/libLLVM-$v.so* /usr/lib/*/libLLVM.so.$v* /usr/lib/llvm-$v/lib/libLLVM*.so*; do
            [ -e "$f" ] && return 0
        done
    done
    return 1
}

have_libusb() {  # a user's PATH may lack /sbin
    { ldconfig -p 2>/dev/null || /sbin/ldconfig -p 2>/dev/null; } | grep -q libusb-1.0
}

missing=""
have_llvm19 || missing="$missing libllvm19"
have_libusb || missing="$missing libusb-1.0-0"
[ -z "$missing" ] && exit 0

if [ "$(id -u)" = 0 ]; then
    as_root=""
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    as_root="sudo -n"
else
    echo "system-deps.sh: not root: install$missing yourself (apt-get install$missing)" >&2
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "system-deps.sh: no apt-get: install$missing (or their equivalents) yourself" >&2
    exit 0
fi
echo "system-deps.sh: installing$missing" >&2
# shellcheck disable=SC2086 -- one word per package
$as_root apt-get install -y -qq $missing >/dev/null 2>&1 \
    || { $as_root apt-get update -qq && $as_root apt-get install -y -qq $missing >/dev/null; } \
    || echo "system-deps.sh: could not install$missing" >&2
exit 0
