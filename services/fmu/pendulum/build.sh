#!/bin/sh
# Builds the pendulum FMU: ./build.sh 2|3 OUT.fmu  (needs cc and python3; Linux or macOS).
# The same as `looplab_shared::scenarios::declared::fmu::build_fmu`, which the tests call.
set -eu
version=${1:?usage: ./build.sh 2|3 OUT.fmu}
out=$(cd "$(dirname "${2:?usage: ./build.sh 2|3 OUT.fmu}")" && pwd)/$(basename "$2")
here=$(cd "$(dirname "$0")" && pwd)
machine=$(uname -m); os=$(uname -s | tr A-Z a-z); ext=so
[ "$os" = darwin ] && ext=dylib
if [ "$version" = 2 ]; then platform=${os}64; else platform=$machine-$os; fi
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
mkdir -p "$work/binaries/$platform"
# -ffp-contract=off: no fused multiply-adds, so Model Exchange matches LoopLab's pendulum bit for bit.
cc -std=c99 -O2 -ffp-contract=off -fPIC -shared -I"$here/headers/fmi$version" -I"$here" "$here/fmi$version.c" \
   -o "$work/binaries/$platform/pendulum.$ext" -lm
cp "$here/modelDescription$version.xml" "$work/modelDescription.xml"
rm -f "$out"
(cd "$work" && python3 -m zipfile -c "$out" modelDescription.xml binaries)
echo "$out"
