include_guard(GLOBAL)
# Warnings are private to our own targets; consumers of the installed package never see them.
function(softshell_set_warnings target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
      -Wold-style-cast -Woverloaded-virtual -Wnull-dereference -Wimplicit-fallthrough>
    $<$<COMPILE_LANGUAGE:C>:-Wall -Wextra -Wpedantic>)
  if(SOFTSHELL_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# Adds a library of one layer: softshell_<name> with alias softshell::<name>, installed and exported.
function(softshell_add_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES" ${ARGN})
  add_library(softshell_${name} ${ARG_SOURCES})
  add_library(softshell::${name} ALIAS softshell_${name})
  set_target_properties(softshell_${name} PROPERTIES
    EXPORT_NAME ${name}
    OUTPUT_NAME softshell_${name}
    VERSION ${PROJECT_VERSION}
    SOVERSION ${PROJECT_VERSION_MAJOR})
  softshell_set_warnings(softshell_${name})
  install(TARGETS softshell_${name} EXPORT softshellTargets
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
    INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()
