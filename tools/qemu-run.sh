#!/usr/bin/env bash
# Runs a Cortex-M4F ELF in QEMU (ARM MPS2 AN386) with semihosting; QEMU's exit status is the
# firmware's. Frames of a defmt logger on stdout are decoded with defmt-print. Paths the
# firmware opens are relative to the current directory. Extra QEMU options: $QEMU_EXTRA; UART0's
# backend: $QEMU_SERIAL (QEMU's -serial argument, e.g. file:PATH; default null).
set -euo pipefail
elf="$1"; shift
qemu=(qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none
  -serial "${QEMU_SERIAL:-null}" -semihosting-config enable=on,target=native -icount shift=0,sleep=off
  -kernel "$elf" ${QEMU_EXTRA:-} "$@")
if grep -qa '_defmt_version_' "$elf"; then
  "${qemu[@]}" | defmt-print -e "$elf"
else
  "${qemu[@]}"
fi
