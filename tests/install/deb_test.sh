#!/usr/bin/env bash
# ctest `deb` (tests/CMakeLists.txt): the Debian package of this build (docs/install.md).
#   1. `cpack -G DEB` makes libbtf_VERSION_ARCH.deb;
#   2. its Depends (dpkg-shlibdeps) names the Debian package of every shared library that any
#      program or library in it loads, as resolved on this machine: so apt pulls them in on a
#      fresh machine of this Debian release;
#   3. apt-get accepts it (`apt-get install --simulate ./libbtf_*.deb` against this machine's
#      package database);
#   4. dpkg installs it into an empty scratch root (its own dpkg database, --force-depends because
#      that root holds no other package), and btf-info --version, btf-synth and the Python module
#      run from there with this machine's system libraries, carrying no path into the build tree
#      (btf-eval render: the image plugin found in usr/lib/libbtf; btf-synth: its tool module
#      found there).
# Not proven: installing into a truly fresh Debian root (needs the network to fetch the
# dependencies; docs/install.md says how to check that by hand).
# Usage: deb_test.sh BUILD_DIR VERSION [PYTHON]
set -euo pipefail
build=$1 version=$2 python=${3:-}
work=$build/deb-test
rm -rf "$work"
mkdir -p "$work"
fail() { echo "deb test: FAILED: $*" >&2; exit 1; }

(cd "$build" && cpack -G DEB -B "$work/pkg") >"$work/cpack.log" 2>&1 || { cat "$work/cpack.log" >&2; fail "cpack -G DEB"; }
deb=$(ls "$work"/pkg/libbtf_"$version"_*.deb)
[ "$(dpkg-deb -f "$deb" Package)" = libbtf ] || fail "package name"
[ "$(dpkg-deb -f "$deb" Version)" = "$version" ] || fail "package version"
depends=$(dpkg-deb -f "$deb" Depends)
echo "$(basename "$deb"): $(du -h "$deb" | cut -f1), Depends: $depends"

root=$work/root
mkdir -p "$root/var/lib/dpkg/info" "$root/var/lib/dpkg/updates" "$work/shim"
touch "$root/var/lib/dpkg/status" "$root/var/lib/dpkg/available"
# The package's postinst runs `ldconfig`. The scratch root has no shell to chroot into, so the
# scripts run outside it (--force-script-chrootless, DPKG_ROOT set) with a stand-in ldconfig that
# makes the soname links in the scratch root instead of rewriting this machine's cache.
printf '#!/bin/sh\nexec /sbin/ldconfig -N -n "$DPKG_ROOT/usr/lib"\n' >"$work/shim/ldconfig"
chmod +x "$work/shim/ldconfig"
PATH=$work/shim:$PATH dpkg --root="$root" --force-depends --force-not-root --force-script-chrootless --log=/dev/null \
  -i "$deb" >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log" >&2; fail "dpkg -i into $root"; }
[ "$(dpkg --root="$root" -s libbtf | sed -n 's/^Status: //p')" = "install ok installed" ] || fail "dpkg -s libbtf in $root"

# 2. every shared library an ELF file of the package loads directly (NEEDED; what those load in
#    turn is their packages' business) comes from a package in Depends, or from this package.
dep_names=" $(sed 's/([^)]*)//g; s/|/,/g' <<<"$depends" | tr -d ' ' | tr ',' ' ') "
declare -A owner=()  # library path -> "package and what it provides", each looked up once
checked=0
while IFS= read -r f; do
  file -b "$f" | grep -q '^ELF.*dynamically linked' || continue
  readelf -d "$f" | grep -q "R.*PATH.*$build" && fail "$f has an RPATH into the build tree"
  resolved=$(LD_LIBRARY_PATH=$root/usr/lib ldd "$f")
  for lib in $(readelf -d "$f" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p'); do
    [[ $lib == libbtf_* || $lib == ld-linux* ]] && continue
    path=$(awk -v l="$lib" '$1 == l && $2 == "=>" { print $3 }' <<<"$resolved")
    [ -n "$path" ] && [ "$path" != "not" ] || fail "${f#"$root"}: $lib not found"
    if [ -z "${owner[$path]:-}" ]; then
      pkg=$(dpkg -S "$path" 2>/dev/null || dpkg -S "$(readlink -f "$path")" 2>/dev/null) || fail "$lib ($path): no package owns it"
      pkg=${pkg%%:*}
      owner[$path]="$pkg $(dpkg-query -W -f='${Provides}' "$pkg" | sed 's/([^)]*)//g' | tr -d ' ' | tr ',' ' ')"
    fi
    ok=0
    for p in ${owner[$path]}; do
      case "$dep_names" in *" $p "*) ok=1 ;; esac
    done
    [ $ok = 1 ] || fail "${f#"$root"} loads $lib from package ${owner[$path]%% *}, which Depends does not name"
    checked=$((checked + 1))
  done
done < <(find "$root/usr" -type f \( -perm -u+x -o -name '*.so*' \))
[ $checked -gt 0 ] || fail "no shared library dependency was checked"
echo "Depends covers the $checked direct library loads (NEEDED) of the package's programs and libraries"

# 3. apt's resolver accepts it here.
apt-get install --simulate -o Debug::NoLocking=1 "$deb" >"$work/apt.log" 2>&1 || { cat "$work/apt.log" >&2; fail "apt-get install --simulate"; }
grep -q '^Inst libbtf ' "$work/apt.log" || { cat "$work/apt.log" >&2; fail "apt-get would not install libbtf"; }
echo "apt-get install --simulate: $(grep -c '^Inst ' "$work/apt.log") package(s) to install ($(grep '^Inst ' "$work/apt.log" | cut -d' ' -f2 | tr '\n' ' '))"

# 4. the installed programs run from the scratch root.
out=$("$root/usr/bin/btf-info" --version)
[ "$out" = "btf-info $version" ] || fail "btf-info --version printed '$out'"
"$root/usr/bin/btf-synth" btf --views 0,1 --lights 0,3 --resolution 4 --samples 1 -q -o "$work/d.h5"
"$root/usr/bin/btf-info" --json "$work/d.h5" | grep -q '"views": *2' || fail "btf-info from the package on a btf-synth dataset"
"$root/usr/bin/btf-compress" "$work/d.h5" --method pca-view -c 1 -q -o "$work/c.h5"
"$root/usr/bin/btf-eval" render "$work/c.h5" -o "$work/r.png" --size 16x12 -q  # the image plugin, from usr/lib/libbtf
[ -s "$work/r.png" ] || fail "btf-eval render from the package wrote no PNG"
echo "from $root/usr/bin: '$out', btf-synth + btf-info + btf-compress + btf-eval render ok"
if [ -n "$python" ]; then
  out=$(PYTHONPATH=$root/usr/lib/python3/dist-packages "$python" -c "import libbtf; print(libbtf.__file__, libbtf.open('$work/d.h5').shape)")
  [ "$out" = "$root/usr/lib/python3/dist-packages/$(cd "$root/usr/lib/python3/dist-packages" && ls libbtf*.so) (2, 2, 4, 4, 3)" ] ||
    fail "python module from the package: '$out'"
  echo "python from the package: ok"
fi
