# What `cmake --install` puts under the prefix, and the Debian package cpack makes of it
# (docs/install.md):
#   bin/btf-*                                  the tools (libbtf linked statically)
#   lib/libbtf_<module>.a, .so                 the libraries (static; shared with BTF_SHARED_LIBS)
#   include/libbtf/<module>/*.h                the headers, export/schneider_reference_decoder.h too
#   lib/cmake/libbtf/                          find_package(libbtf CONFIG): libbtf::btf, libbtf::<module>
#   lib/pkgconfig/libbtf.pc                    pkg-config
#   lib/python3/dist-packages/libbtf*.so       the Python module (BTF_PYTHON; python/CMakeLists.txt)
#   share/doc/libbtf/                          README.md and docs/
include(CMakePackageConfigHelpers)

install(TARGETS ${BTF_TOOL_TARGETS} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR})

set(BTF_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/libbtf)
install(EXPORT libbtf-static-targets NAMESPACE libbtf:: DESTINATION ${BTF_CMAKE_DIR})
if(BTF_SHARED_LIBS)
  install(EXPORT libbtf-shared-targets NAMESPACE libbtf:: DESTINATION ${BTF_CMAKE_DIR})
endif()
# hdf5::hdf5 as found for this build, for libbtfConfig.cmake to recreate: FindHDF5 try-compiles C,
# which fails in a consumer whose project() enables only CXX.
set(BTF_HDF5_LOCATION "")
foreach(property IMPORTED_LOCATION IMPORTED_LOCATION_RELEASE IMPORTED_LOCATION_RELWITHDEBINFO)
  get_target_property(location hdf5::hdf5 ${property})
  if(location AND NOT BTF_HDF5_LOCATION)
    set(BTF_HDF5_LOCATION ${location})
  endif()
endforeach()
foreach(property INCLUDE_DIRECTORIES COMPILE_DEFINITIONS LINK_LIBRARIES)
  get_target_property(value hdf5::hdf5 INTERFACE_${property})
  set(BTF_HDF5_${property} "")
  if(value)
    set(BTF_HDF5_${property} "${value}")
  endif()
endforeach()
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/libbtfConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/libbtfConfig.cmake INSTALL_DESTINATION ${BTF_CMAKE_DIR})
# 0.x: a minor release may change the API, so only the same major.minor is compatible.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/libbtfConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/libbtfConfig.cmake ${PROJECT_BINARY_DIR}/libbtfConfigVersion.cmake
        DESTINATION ${BTF_CMAKE_DIR})

# libbtf.pc: -lbtf_<module> for every module, dependents first (BTF_MODULES is in dependency order).
set(BTF_PC_LIBS "")
foreach(m ${BTF_MODULES})
  set(BTF_PC_LIBS "-lbtf_${m} ${BTF_PC_LIBS}")
endforeach()
string(STRIP "${BTF_PC_LIBS}" BTF_PC_LIBS)
configure_file(${PROJECT_SOURCE_DIR}/cmake/libbtf.pc.in ${PROJECT_BINARY_DIR}/libbtf.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/libbtf.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

# cpack -G DEB: one package "libbtf" of everything above, installed under /usr. Depends is
# computed by dpkg-shlibdeps from the binaries (Debian: dpkg-dev); Recommends lists what a C++
# consumer's compiler (the public headers' dependencies) and the Python module need.
set(CPACK_PACKAGE_NAME libbtf)
set(CPACK_PACKAGE_VENDOR "libbtf")
set(CPACK_PACKAGE_CONTACT "libbtf maintainers <libbtf@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "BTF toolkit: measurement photos to compact BTF codecs (tools, C++ library, Python module)")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_GENERATOR DEB)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# Our own shared libraries link each other: dpkg-shlibdeps finds them in the package (a path
# relative to the package root, where cpack runs it).
string(REGEX REPLACE "^/" "" package_prefix "${CPACK_PACKAGING_INSTALL_PREFIX}")
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS_PRIVATE_DIRS ${package_prefix}/${CMAKE_INSTALL_LIBDIR})
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "libeigen3-dev, libfmt-dev, nlohmann-json3-dev, libhdf5-dev, python3, python3-numpy")
include(CPack)
