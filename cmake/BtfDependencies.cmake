# All third-party dependencies are Debian packages (see ./run for the list); nothing is vendored.
find_package(Threads REQUIRED)
find_package(OpenMP REQUIRED)
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(fmt REQUIRED)
find_package(spdlog REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(CLI11 REQUIRED)
# OpenImageIO's exported targets reference its tools: the package openimageio-tools must be installed.
find_package(OpenImageIO REQUIRED)
find_package(OpenCV REQUIRED COMPONENTS core imgproc calib3d aruco)
find_package(apriltag REQUIRED)
# libzip (Debian: libzip-dev) reads zipped image sets; through pkg-config, since libzip's CMake
# package needs its command-line tools installed.
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBZIP REQUIRED IMPORTED_TARGET libzip)
# libdeflate (Debian: libdeflate-dev) inflates dataset chunks on the compute threads (libbtf/io/raw_chunks.h).
pkg_check_modules(LIBDEFLATE REQUIRED IMPORTED_TARGET libdeflate)
# HDF5 (C library; libbtf::io links hdf5::hdf5 publicly). The installed package config recreates
# this target from its properties (cmake/BtfPackage.cmake) rather than running FindHDF5 again.
set(HDF5_PREFER_PARALLEL OFF)
find_package(HDF5 REQUIRED COMPONENTS C)
# The tools that are executables linking libbtf (tools/CMakeLists.txt) link HDF5's static archive
# (libhdf5-dev ships it): the shared library's own dependencies, libcurl and some 30 libraries for
# a remote-file driver libbtf never uses, cost every start of a program ~16 ms (docs/performance.md,
# "Tool start-up"). The archive pulls only the drivers and filters libbtf calls, which need szip,
# zlib and libm. Off, or without the archive: the shared library, as for everything else.
option(BTF_TOOLS_STATIC_HDF5 "Tools link HDF5's static archive (libhdf5.a) when it is installed" ON)
set(BTF_HDF5_STATIC_LIBS "")
if(BTF_TOOLS_STATIC_HDF5 AND HDF5_C_LIBRARY_hdf5)
  get_filename_component(dir "${HDF5_C_LIBRARY_hdf5}" DIRECTORY)
  find_file(BTF_HDF5_STATIC_ARCHIVE libhdf5.a HINTS "${dir}" NO_DEFAULT_PATH)
  if(BTF_HDF5_STATIC_ARCHIVE)
    set(BTF_HDF5_STATIC_LIBS ${BTF_HDF5_STATIC_ARCHIVE} ${HDF5_C_LIBRARY_sz} ${HDF5_C_LIBRARY_z} ${CMAKE_DL_LIBS} m)
    add_library(btf_hdf5_static INTERFACE)  # hdf5::hdf5's headers and definitions, the archive's link
    target_include_directories(btf_hdf5_static INTERFACE $<TARGET_PROPERTY:hdf5::hdf5,INTERFACE_INCLUDE_DIRECTORIES>)
    target_compile_definitions(btf_hdf5_static INTERFACE $<TARGET_PROPERTY:hdf5::hdf5,INTERFACE_COMPILE_DEFINITIONS>)
    target_link_libraries(btf_hdf5_static INTERFACE ${BTF_HDF5_STATIC_LIBS})
  endif()
endif()
message(STATUS "libbtf: tools link HDF5 statically: ${BTF_HDF5_STATIC_LIBS}")
# MPI (Open MPI from Debian: libopenmpi-dev, openmpi-bin) for distributed runs (docs/scaling.md);
# optional: without it every tool runs as one process.
option(BTF_WITH_MPI "Distributed runs over MPI when MPI is found" ON)
set(BTF_HAVE_MPI OFF)
set(BTF_MPI_TARGET "")       # what btf_core links privately
set(BTF_PC_MPI "")           # libbtf.pc Requires.private
if(BTF_WITH_MPI)
  find_package(MPI COMPONENTS CXX)
  if(MPI_CXX_FOUND)
    set(BTF_HAVE_MPI ON)
    set(BTF_MPI_TARGET MPI::MPI_CXX)
    set(BTF_PC_MPI ompi-cxx)
  endif()
endif()
message(STATUS "libbtf: distributed runs over MPI: ${BTF_HAVE_MPI}")
if(BTF_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(BTF_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)
endif()
# The Python module (python/, BTF_PYTHON): pybind11, the interpreter's headers and NumPy (Debian:
# pybind11-dev, python3-dev, python3-numpy; python3-pytest runs its tests). ./run passes
# -DPython3_EXECUTABLE=/usr/bin/python3, the interpreter those packages are for.
set(BTF_PYTHON_FOUND OFF)
if(NOT BTF_PYTHON STREQUAL "OFF")
  set(required "")
  if(BTF_PYTHON STREQUAL "ON")
    set(required REQUIRED)
  endif()
  find_package(Python3 3.8 COMPONENTS Interpreter Development.Module NumPy ${required})
  if(Python3_FOUND AND Python3_NumPy_FOUND)
    find_package(pybind11 2.6 CONFIG ${required})
  endif()
  if(Python3_FOUND AND Python3_NumPy_FOUND AND pybind11_FOUND)
    set(BTF_PYTHON_FOUND ON)
  else()
    message(STATUS "Python module libbtf: not built (needs pybind11-dev, python3-dev and python3-numpy for "
                   "the interpreter '${Python3_EXECUTABLE}'; choose another with -DPython3_EXECUTABLE=...)")
  endif()
endif()
