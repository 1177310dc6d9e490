# cmake -P script: configures and builds the CMake project SOURCE against the installed package the
# way an outside project would, with find_* restricted to VIEW (CMAKE_FIND_ROOT_PATH, mode ONLY: a
# missing private dependency fails find_package), then checks what the build actually used
# (ninja -t deps, ninja -t commands): no header and no library of a private dependency.
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
  set(out "${out}" PARENT_SCOPE)
endfunction()

file(REMOVE_RECURSE ${BUILD})
set(launchers "")
if(CXX_LAUNCHER)
  list(APPEND launchers -DCMAKE_CXX_COMPILER_LAUNCHER=${CXX_LAUNCHER} -DCMAKE_C_COMPILER_LAUNCHER=${CXX_LAUNCHER})
endif()
# (A static build's archives need the private dependencies too: then nothing is restricted.)
set(restrict "")
if(SHARED)
  set(restrict -DCMAKE_FIND_ROOT_PATH=${VIEW}
      -DCMAKE_FIND_ROOT_PATH_MODE_PACKAGE=ONLY -DCMAKE_FIND_ROOT_PATH_MODE_LIBRARY=ONLY
      -DCMAKE_FIND_ROOT_PATH_MODE_INCLUDE=ONLY -DCMAKE_FIND_ROOT_PATH_MODE_PROGRAM=NEVER)
endif()
run(${CMAKE_COMMAND} -S ${SOURCE} -B ${BUILD} -G ${GENERATOR} -DCMAKE_BUILD_TYPE=Release
    -DCMAKE_C_COMPILER=${C_COMPILER} -DCMAKE_CXX_COMPILER=${CXX_COMPILER} ${launchers}
    "-DCMAKE_CXX_FLAGS=${FLAGS}" "-DCMAKE_C_FLAGS=${FLAGS}"
    -DCMAKE_PREFIX_PATH=${PREFIX} ${restrict})
run(${CMAKE_COMMAND} --build ${BUILD})

if(NOT SHARED)
  message(STATUS "built ${SOURCE} against the static package ${PREFIX}")
  return()
endif()
if(NOT GENERATOR STREQUAL "Ninja")
  message(STATUS "built ${SOURCE}; (the header and library check needs the Ninja generator)")
  return()
endif()
run(ninja -C ${BUILD} -t deps)
set(deps "${out}")
run(ninja -C ${BUILD} -t commands)
set(commands "${out}")
foreach(header IN LISTS PRIVATE_HEADERS)
  string(FIND "${deps}" "${header}" at)
  if(NOT at EQUAL -1)
    string(REGEX MATCH "[^\n]*${header}[^\n]*" line "${deps}")
    message(FATAL_ERROR "${SOURCE} was compiled with a private dependency's header: ${line}")
  endif()
endforeach()
foreach(library IN LISTS PRIVATE_LIBRARIES)
  if(commands MATCHES "${library}")
    message(FATAL_ERROR "${SOURCE} was linked with a private dependency (${library}):\n${commands}")
  endif()
endforeach()
string(REGEX MATCHALL "\n +/[^\n]+" headers "${deps}")
list(LENGTH headers n_headers)
message(STATUS "built ${SOURCE} against ${PREFIX} (${n_headers} headers read, none of a private dependency; "
               "no private library linked)")
