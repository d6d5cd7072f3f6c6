#!/bin/sh
# Installs Debian's chromium when it is missing: the viewer's end-to-end test
# (tests/test_viewer_browser.py) drives it headless over the DevTools
# protocol, its WebGL2 on SwiftShader (no GPU needed). Idempotent.
set -eu
exe=${OCLGI_CHROMIUM:-chromium}
if command -v "$exe" >/dev/null 2>&1; then
    exit 0
fi
echo "oclgi: $exe not found; installing Debian's chromium (for the viewer's browser test)" >&2
if [ "$(id -u)" != 0 ]; then
    SUDO=sudo
else
    SUDO=
fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
if ! command -v "$exe" >/dev/null 2>&1; then
    echo "oclgi: chromium was installed but $exe is still not on the PATH" >&2
    exit 1
fi
