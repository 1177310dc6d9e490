# cmake -P script: installs softshell into STAGE, then moves the prefix to PREFIX (an install that
# was unpacked or moved elsewhere must still work), and builds VIEW: the only directory the
# consumers' find_* calls may search (see CMakeLists.txt). Checks what can be checked without
# running anything:
#  - installed programs and libraries carry relative RUNPATHs only ($ORIGIN...), none pointing
#    into the build tree, the stage or the source tree;
#  - libsoftshell_plugin is one file (no versioned name, no symlinks);
#  - with shared libraries, the installed CMake files name none of the private dependencies.
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "failed (${rc}): ${ARGN}\n${out}\n${err}")
  endif()
endfunction()

file(REMOVE_RECURSE ${STAGE} ${PREFIX} ${VIEW})
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${STAGE})
get_filename_component(parent ${PREFIX} DIRECTORY)
file(MAKE_DIRECTORY ${parent})
file(RENAME ${STAGE} ${PREFIX})

# RUNPATHs of every ELF file installed.
file(GLOB_RECURSE installed LIST_DIRECTORIES false ${PREFIX}/bin/* ${PREFIX}/lib/*.so*)
set(programs 0)
foreach(f IN LISTS installed)
  if(IS_SYMLINK ${f})
    continue()
  endif()
  execute_process(COMMAND readelf -d ${f} OUTPUT_VARIABLE dyn ERROR_QUIET)
  string(REGEX MATCH "\\((RUNPATH|RPATH)\\)[^[]*\\[([^]]*)\\]" hit "${dyn}")
  set(path "${CMAKE_MATCH_2}")
  foreach(entry IN LISTS path)
    string(REPLACE ":" ";" entries "${entry}")
    foreach(e IN LISTS entries)
      if(NOT e MATCHES "^\\$ORIGIN")
        message(FATAL_ERROR "${f} has an absolute RUNPATH entry '${e}' (RUNPATH: ${path})")
      endif()
    endforeach()
  endforeach()
  if(f MATCHES "/bin/")
    math(EXPR programs "${programs} + 1")
    if(NOT path MATCHES "^\\$ORIGIN/")
      message(FATAL_ERROR "the installed program ${f} has no RUNPATH relative to itself (RUNPATH: '${path}')")
    endif()
  endif()
endforeach()
if(programs EQUAL 0)
  message(FATAL_ERROR "no installed programs found in ${PREFIX}/bin")
endif()

file(GLOB plugin_files ${PREFIX}/lib/libsoftshell_plugin*)
if(NOT plugin_files STREQUAL "${PREFIX}/lib/libsoftshell_plugin.so" OR IS_SYMLINK ${PREFIX}/lib/libsoftshell_plugin.so)
  message(FATAL_ERROR "libsoftshell_plugin should be one file, found: ${plugin_files}")
endif()

if(SHARED)
  file(GLOB cmake_files ${PREFIX}/lib/cmake/softshell/*.cmake)
  foreach(f IN LISTS cmake_files)
    file(READ ${f} text)
    string(REGEX REPLACE "#[^\n]*" "" text "${text}")  # what it does, not what its comments say
    string(TOLOWER "${text}" text)
    foreach(private cholmod suitesparse httplib nlohmann openssl opensubdiv osdcpu)
      if(text MATCHES "${private}")
        message(FATAL_ERROR "${f} names the private dependency '${private}'")
      endif()
    endforeach()
  endforeach()
endif()

# VIEW: symlinks to the relocated prefix and to the public dependencies' development files only.
foreach(p IN LISTS PREFIX VISIBLE)
  get_filename_component(dir ${VIEW}${p} DIRECTORY)
  file(MAKE_DIRECTORY ${dir})
  file(CREATE_LINK ${p} ${VIEW}${p} SYMBOLIC)
endforeach()
message(STATUS "installed into ${STAGE}, moved to ${PREFIX}; ${programs} programs with relative RUNPATHs; view ${VIEW}")
