#!/usr/bin/env bash
# Installs what ferrosid's tests need on a machine that has only the Rust toolchain, idempotently:
#   - the thumbv7em-none-eabihf Rust target (rustup target add)   -> firmware images
#   - qemu-system-arm (Debian package qemu-system-arm)            -> runs them (mps2-an386)
#   - llvm-size, llvm-objdump, llvm-symbolizer (Debian package llvm) -> sizes, panic-path scan
# Does nothing (and touches no network) when everything is already present.
# Exit status: 0 when everything is available afterwards, 1 otherwise (with what to do).
set -euo pipefail

TARGET=thumbv7em-none-eabihf
say() { printf 'setup: %s\n' "$*"; }
fail() { printf 'setup: ERROR: %s\n' "$*" >&2; exit 1; }

# --- Rust toolchain and the Cortex-M4F target -------------------------------------------------
command -v cargo >/dev/null 2>&1 || fail "cargo not found on PATH: install the Rust toolchain with rustup first."
command -v rustc >/dev/null 2>&1 || fail "rustc not found on PATH: install the Rust toolchain with rustup first."

sysroot=$(rustc --print sysroot)
if [ ! -d "$sysroot/lib/rustlib/$TARGET/lib" ]; then
    command -v rustup >/dev/null 2>&1 \
        || fail "the Rust target $TARGET is missing and rustup is not available: install it with your toolchain manager (rustup target add $TARGET)."
    say "installing Rust target $TARGET (rustup target add)"
    rustup target add "$TARGET" \
        || fail "'rustup target add $TARGET' failed (no network?). Run it by hand once the network is reachable."
fi

# --- Debian packages -----------------------------------------------------------------------------
# command name -> Debian package
declare -A PKG_OF=([qemu-system-arm]=qemu-system-arm [llvm-size]=llvm [llvm-objdump]=llvm [llvm-symbolizer]=llvm)
missing=()
for cmd in qemu-system-arm llvm-size llvm-objdump llvm-symbolizer; do
    if ! command -v "$cmd" >/dev/null 2>&1; then
        pkg=${PKG_OF[$cmd]}
        case " ${missing[*]} " in *" $pkg "*) ;; *) missing+=("$pkg") ;; esac
    fi
done

if [ ${#missing[@]} -gt 0 ]; then
    say "missing tools; installing Debian packages: ${missing[*]}"
    command -v apt-get >/dev/null 2>&1 \
        || fail "apt-get not found: install ${missing[*]} (qemu-system-arm, llvm-size) with your package manager."
    if [ "$(id -u)" -eq 0 ]; then
        SUDO=()
    elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        SUDO=(sudo -n)
    else
        fail "need root to install ${missing[*]}: run 'sudo apt-get update && sudo apt-get install -y ${missing[*]}' (or run this script as root)."
    fi
    export DEBIAN_FRONTEND=noninteractive
    "${SUDO[@]}" apt-get -o DPkg::Lock::Timeout=300 update -qq \
        || fail "'apt-get update' failed (no network or broken sources?): install ${missing[*]} by hand."
    "${SUDO[@]}" apt-get -o DPkg::Lock::Timeout=300 install -y -qq --no-install-recommends "${missing[@]}" >/dev/null \
        || fail "'apt-get install ${missing[*]}' failed: install them by hand."
fi

for cmd in qemu-system-arm llvm-size llvm-objdump llvm-symbolizer timeout; do
    command -v "$cmd" >/dev/null 2>&1 || fail "$cmd is still not on PATH after installation."
done
say "ok: rust target $TARGET, $(qemu-system-arm --version | head -n1), $(llvm-size --version | grep -m1 -i version | sed 's/^ *//')"
