#!/bin/sh
# Installs Debian's PoCL when the given Python (with pyopencl) sees no OpenCL
# CPU device. Idempotent: does nothing when a device is already there.
set -eu
py=${1:-python3}
probe='import pyopencl as cl, sys
devs = [d for p in cl.get_platforms() for d in p.get_devices(cl.device_type.CPU)]
sys.exit(0 if devs else 1)'
if "$py" -c "$probe" 2>/dev/null; then
    exit 0
fi
echo "oclgi: no OpenCL CPU device found; installing Debian's PoCL (pocl-opencl-icd)" >&2
if [ "$(id -u)" != 0 ]; then
    SUDO=sudo
else
    SUDO=
fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd ocl-icd-libopencl1 >/dev/null
if ! "$py" -c "$probe"; then
    echo "oclgi: PoCL was installed but still no OpenCL CPU device is visible" >&2
    exit 1
fi
