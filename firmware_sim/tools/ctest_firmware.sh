#!/usr/bin/env bash
# ctest entry for the Cortex-M4F firmware: `make check` into BUILD_DIR (skip with 77 when the
# ARM toolchain, QEMU or the Python simulator is missing).
set -euo pipefail
build_dir=$1
python=$2
here=$(cd "$(dirname "$0")/.." && pwd)
for tool in arm-none-eabi-gcc arm-none-eabi-g++ qemu-system-arm make; do
  if ! command -v "$tool" >/dev/null; then
    echo "skip: $tool not installed"
    exit 77
  fi
done
if ! "$python" -c "import dualprobe.simulate" 2>/dev/null; then
  echo "skip: dualprobe.simulate not importable by $python"
  exit 77
fi
exec make -C "$here" -j2 check BUILD="$build_dir" OUT="$build_dir/out" PYTHON="$python"
