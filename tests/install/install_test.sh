#!/usr/bin/env bash
# ctest `install` and `install_more` (tests/CMakeLists.txt): installs this build into a scratch
# prefix and uses it the way another program would (docs/install.md):
#   1. cmake --install BUILD --prefix PREFIX; the installed btf-synth / btf-compress make a
#      dataset and a codec, btf-eval renders a PNG through the image plugin, and no installed
#      program or library links OpenImageIO; btf-register and btf-synth are launchers that link
#      no libbtf, OpenCV, MPI or HDF5 and find their tool modules;
#   2. PARTS, a comma-separated list of
#        shared     tests/install/consumer, an external CMake project, configured with
#                   find_package(libbtf) against PREFIX, built and run (shared libraries; it
#                   must neither look for nor link libbtf's private dependencies); its project()
#                   enables only CXX, and configuring it must not enable C; a missing input must
#                   give it btf::Error's message and exit code 4;
#        static     the same with LIBBTF_USE_STATIC_LIBS=ON (static archives);
#        pkgconfig  the same main.cpp built with the flags of `pkg-config libbtf` alone;
#        python     the Python module imported from PREFIX (not the build tree) reads the dataset;
#      each consumer's output must name this version and the shape, and its RMSE must equal btf-compress's.
# Consumers are compiled through ccache when it is installed (as ./run builds).
# Usage: install_test.sh BUILD_DIR SOURCE_DIR CXX VERSION PARTS [PYTHON]
set -euo pipefail
build=$1 src=$2 cxx=$3 version=$4 parts=",$5," python=${6:-}
work=$build/install-test-${5//,/-}
rm -rf "$work"
mkdir -p "$work"
prefix=$work/prefix
fail() { echo "install test: FAILED: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$prefix" >"$work/install.log"
for f in bin/btf-info bin/btf-synth lib/libbtf_core.a lib/libbtf_core.so lib/cmake/libbtf/libbtfConfig.cmake \
         lib/pkgconfig/libbtf.pc include/libbtf/export/schneider_reference_decoder.h \
         include/libbtf/export/sattler_reference_decoder.h include/libbtf/export/export_reader.h share/doc/libbtf/README.md \
         share/doc/libbtf/errors.md; do
  [ -e "$prefix/$f" ] || fail "cmake --install did not install $f"
done

# Data from the installed tools (4 views x 5 lights x 8 x 8 x RGB).
"$prefix/bin/btf-synth" btf --views 0,1,7,19 --lights 0,3,9,20,40 --resolution 8 --samples 2 -q -o "$work/gt.h5"
"$prefix/bin/btf-compress" "$work/gt.h5" --method pca-view -c 2 -q --json -o "$work/codec.h5" >"$work/compress.json"
want_rmse=$(sed -n 's/.*"rmse": *\([-0-9.eE+]*\).*/\1/p' "$work/compress.json" | head -1)
[ -n "$want_rmse" ] || fail "no rmse in btf-compress --json output ($work/compress.json)"

# Images go through the image plugin <libdir>/libbtf/libbtf_oiio.so, which the installed tools find
# from bin/; no program or libbtf library links OpenImageIO (docs/architecture.md, "The image plugin").
"$prefix/bin/btf-eval" render "$work/codec.h5" -o "$work/render.png" --size 16x12 -q ||
  fail "the installed btf-eval render (image plugin from $prefix/lib/libbtf)"
[ -s "$work/render.png" ] || fail "the installed btf-eval render wrote no PNG"
for f in "$prefix"/bin/btf-* "$prefix"/lib/libbtf_*.so; do
  ! readelf -d "$f" | grep -q 'NEEDED.*OpenImageIO' || fail "$f links OpenImageIO (only the image plugin may)"
done
echo "installed tools: image plugin found, no OpenImageIO in NEEDED"
# btf-register and btf-synth are launchers of their tool modules <libdir>/libbtf/libbtf_tool_<tool>.so
# (docs/architecture.md, "Tool modules"; btf-synth above ran through its module): they link no
# libbtf, OpenCV, MPI or HDF5, and btf-register --help loads its module (OpenCV resolved).
for t in btf-register btf-synth; do
  [ -f "$prefix/lib/libbtf/libbtf_tool_$t.so" ] || fail "cmake --install did not install lib/libbtf/libbtf_tool_$t.so"
  ! readelf -d "$prefix/bin/$t" | grep -Eq 'NEEDED.*(opencv|libbtf|mpi|hdf5)' || fail "the installed $t links what its module should"
done
"$prefix/bin/btf-register" --help >/dev/null || fail "the installed btf-register --help (its module from $prefix/lib/libbtf)"
echo "installed btf-register, btf-synth: launchers, modules found"

check_output() {  # NAME EXE
  local out
  out=$("$2" "$work/gt.h5" "$work/codec.h5") || fail "$1: consumer exited $?"
  grep -qx "version $version" <<<"$out" || fail "$1: expected 'version $version' in: $out"
  grep -qx "shape 4 5 8 8 3" <<<"$out" || fail "$1: expected 'shape 4 5 8 8 3' in: $out"
  local got
  got=$(sed -n 's/^rmse //p' <<<"$out")
  # Both sum squared errors in double over the same float values: 1e-6 relative covers the order.
  awk -v a="$got" -v b="$want_rmse" 'BEGIN { d = a - b; if (d < 0) d = -d; exit !(b > 0 && d <= 1e-6 * b) }' ||
    fail "$1: rmse $got, btf-compress reported $want_rmse"
  echo "$1: ok ($(tr '\n' ' ' <<<"$out"))"
}

launcher=()
command -v ccache >/dev/null && launcher=(ccache)
for kind in shared static; do
  [[ $parts == *",$kind,"* ]] || continue
  static=OFF
  [ $kind = static ] && static=ON
  cmake -S "$src/tests/install/consumer" -B "$work/cmake-$kind" -DCMAKE_PREFIX_PATH="$prefix" \
    -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_CXX_COMPILER_LAUNCHER="${launcher[*]}" -DLIBBTF_USE_STATIC_LIBS=$static >"$work/cmake-$kind.log" 2>&1 ||
    { cat "$work/cmake-$kind.log" >&2; fail "find_package(libbtf) consumer ($kind) did not configure"; }
  grep -q "libbtf $version ($kind) from $prefix/lib/cmake/libbtf" "$work/cmake-$kind.log" ||
    fail "consumer ($kind) did not find libbtf $version in $prefix: $(grep libbtf "$work/cmake-$kind.log")"
  # project(... CXX): neither the consumer nor libbtf's package (HDF5 included) enabled C.
  ! grep '^CMAKE_C_COMPILER:' "$work/cmake-$kind/CMakeCache.txt" ||
    fail "find_package(libbtf) consumer ($kind) enabled the C language"
  cmake --build "$work/cmake-$kind" >"$work/build-$kind.log" 2>&1 ||
    { cat "$work/build-$kind.log" >&2; fail "find_package(libbtf) consumer ($kind) did not build"; }
  if [ $kind = shared ]; then
    readelf -d "$work/cmake-$kind/consumer" | grep -q 'NEEDED.*libbtf_core\.so' || fail "shared consumer does not load libbtf_core.so"
    # Only the public dependencies reach it: libbtf's private ones were neither looked for nor linked.
    ! grep -E '^(OpenCV|OpenImageIO|apriltag)_DIR' "$work/cmake-$kind/CMakeCache.txt" ||
      fail "find_package(libbtf) with the shared libraries looked for a private dependency"
    ! readelf -d "$work/cmake-$kind/consumer" | grep -E 'NEEDED.*(opencv|OpenImageIO|apriltag|libzip|libdeflate|gomp)' ||
      fail "the shared consumer links a private dependency of libbtf"
  else
    ! readelf -d "$work/cmake-$kind/consumer" | grep -q 'NEEDED.*libbtf_' || fail "static consumer loads a libbtf shared library"
  fi
  check_output "find_package ($kind)" "$work/cmake-$kind/consumer"
  # An error inside the library reaches the program as btf::Error with the documented exit code.
  set +e
  err=$("$work/cmake-$kind/consumer" "$work/missing.h5" "$work/codec.h5" 2>&1)
  rc=$?
  set -e
  [ $rc -eq 4 ] && grep -q "consumer: error: .*$work/missing.h5" <<<"$err" ||
    fail "$kind, missing input: exit $rc, '$err' (expected 4)"
  echo "find_package ($kind), missing input: ok (exit 4: $err)"
done

if [[ $parts == *,pkgconfig,* ]]; then
  # pkg-config, nothing else: the flags say where everything is (the shared libraries; rpath so
  # that the program runs from the scratch prefix).
  export PKG_CONFIG_PATH=$prefix/lib/pkgconfig
  [ "$(pkg-config --modversion libbtf)" = "$version" ] || fail "pkg-config --modversion libbtf"
  # shellcheck disable=SC2046
  "${launcher[@]}" "$cxx" -std=c++20 "$src/tests/install/consumer/main.cpp" -o "$work/pkgconfig-consumer" \
    $(pkg-config --cflags --libs libbtf) -Wl,-rpath,"$prefix/lib" 2>"$work/pkgconfig-build.log" ||
    { cat "$work/pkgconfig-build.log" >&2; fail "pkg-config consumer did not build"; }
  check_output "pkg-config" "$work/pkgconfig-consumer"
fi

if [[ $parts == *,python,* ]]; then
  [ -n "$python" ] || fail "no Python interpreter given for the python part"
  pydir=$(find "$prefix" -name 'libbtf*.so' -path '*python3*' -printf '%h\n' | head -1)
  [ -n "$pydir" ] || fail "the Python module was not installed under $prefix"
  out=$(cd "$work" && PYTHONPATH=$pydir "$python" -c "
import libbtf
s = libbtf.open('gt.h5')
assert libbtf.__file__.startswith('$prefix'), libbtf.__file__
print(libbtf.__version__, s.shape, s.view_slot(0).shape)") || fail "python: import libbtf from $pydir"
  [ "$out" = "$version (4, 5, 8, 8, 3) (5, 8, 8, 3)" ] || fail "python from $pydir printed '$out'"
  echo "python from ${pydir#"$prefix"/}: ok ($out)"
fi
