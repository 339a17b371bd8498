# Installs a tprf build into a fresh prefix, then configures, builds and runs tests/consumer against
# it. Run by CTest (tests/CMakeLists.txt) as
#   cmake -DBUILD_DIR=... -DCONSUMER_DIR=... -DWORK_DIR=... -DCONFIG=... -DGENERATOR=...
#         -DCXX_COMPILER=... -DSANITIZE=... -DSCENE=... -P check_install.cmake
foreach(var BUILD_DIR CONSUMER_DIR WORK_DIR GENERATOR CXX_COMPILER SCENE)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_install.cmake: ${var} is not set")
  endif()
endforeach()

file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")
set(install_config)
set(build_type Release)
if(CONFIG)
  set(install_config --config "${CONFIG}")
  set(build_type "${CONFIG}")
endif()
execute_process(COMMAND "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${prefix}" ${install_config}
                OUTPUT_QUIET COMMAND_ERROR_IS_FATAL ANY)

# A sanitized libtprf.a needs the sanitizer runtime in whatever links it.
set(flags)
if(SANITIZE)
  set(flags "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined"
            "-DCMAKE_EXE_LINKER_FLAGS=-fsanitize=address,undefined")
endif()
execute_process(COMMAND "${CMAKE_COMMAND}" -S "${CONSUMER_DIR}" -B "${WORK_DIR}/build" -G "${GENERATOR}"
                        "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}" "-DCMAKE_BUILD_TYPE=${build_type}"
                        "-DCMAKE_PREFIX_PATH=${prefix}" "-DTPRF_EXPECTED_PREFIX=${prefix}" ${flags}
                COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${CMAKE_COMMAND}" --build "${WORK_DIR}/build" COMMAND_ERROR_IS_FATAL ANY)
execute_process(COMMAND "${WORK_DIR}/build/tprf_consumer" "${SCENE}" COMMAND_ERROR_IS_FATAL ANY)
