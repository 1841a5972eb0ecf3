# dualprobe::c — the C API (cpp/include/dualprobe/dualprobe.h) as a static library over the
# header-only core. Built without exceptions or RTTI, as firmware links it.
if(SKBUILD)
  return()  # the Python wheel needs neither the C library nor its install rules
endif()

add_library(dualprobe_c STATIC ${PROJECT_SOURCE_DIR}/cpp/src/dualprobe_c.cpp
  ${PROJECT_SOURCE_DIR}/cpp/src/dualprobe_svf_c.cpp
  ${PROJECT_SOURCE_DIR}/cpp/src/dualprobe_kalman_c.cpp)
add_library(dualprobe::c ALIAS dualprobe_c)
set_target_properties(dualprobe_c PROPERTIES
  EXPORT_NAME c
  OUTPUT_NAME dualprobe_c
  POSITION_INDEPENDENT_CODE ON)
target_link_libraries(dualprobe_c PUBLIC dualprobe::core)
target_compile_options(dualprobe_c PRIVATE ${DUALPROBE_WARNINGS} -fno-exceptions -fno-rtti)
# The same arithmetic on every target: no FMA contraction (firmware_sim/README.md).
target_compile_options(dualprobe_c PRIVATE -ffp-contract=off)
target_compile_definitions(dualprobe_c PRIVATE EIGEN_NO_DEBUG)
if(UNIX)
  target_link_libraries(dualprobe_c PRIVATE m)
endif()
if(DUALPROBE_SANITIZE)
  target_compile_options(dualprobe_c PRIVATE
    -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer)
endif()
