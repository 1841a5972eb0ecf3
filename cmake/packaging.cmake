# Install rules and an exported package so that firmware (or any CMake project) does
#   find_package(dualprobe CONFIG REQUIRED)
#   target_link_libraries(app PRIVATE dualprobe::c)      # or dualprobe::core (C++ templates)
if(SKBUILD)
  return()
endif()

include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(DUALPROBE_CMAKE_INSTALL_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/dualprobe)
set_target_properties(dualprobe_core PROPERTIES EXPORT_NAME core)

install(TARGETS dualprobe_core dualprobe_c
  EXPORT dualprobeTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/cpp/include/dualprobe
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
  FILES_MATCHING PATTERN "*.hpp" PATTERN "*.h")
install(EXPORT dualprobeTargets
  NAMESPACE dualprobe::
  DESTINATION ${DUALPROBE_CMAKE_INSTALL_DIR})

configure_package_config_file(
  ${CMAKE_CURRENT_LIST_DIR}/dualprobeConfig.cmake.in
  ${PROJECT_BINARY_DIR}/dualprobeConfig.cmake
  INSTALL_DESTINATION ${DUALPROBE_CMAKE_INSTALL_DIR})
# Header-only core plus a static library built per toolchain: any 0.x of the same minor is
# source compatible.
write_basic_package_version_file(
  ${PROJECT_BINARY_DIR}/dualprobeConfigVersion.cmake
  VERSION ${PROJECT_VERSION}
  COMPATIBILITY SameMinorVersion)
install(FILES
  ${PROJECT_BINARY_DIR}/dualprobeConfig.cmake
  ${PROJECT_BINARY_DIR}/dualprobeConfigVersion.cmake
  DESTINATION ${DUALPROBE_CMAKE_INSTALL_DIR})
