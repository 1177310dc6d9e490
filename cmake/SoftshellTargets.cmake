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

# Adds the library of one layer: softshell_<name> with alias softshell::<name>, installed and
# exported. The layer's folder holds include/softshell/ (its public headers, installed) and src/.
#   softshell_add_library(<name> SOURCES ... [PUBLIC_LIBS ...] [PRIVATE_LIBS ...] [EXPORT <set>])
# EXPORT: the export set (default softshellTargets; the Bullet bridge has its own, loaded only by
# find_package(softshell COMPONENTS bullet)).
function(softshell_add_library name)
  cmake_parse_arguments(ARG "" "EXPORT" "SOURCES;PUBLIC_LIBS;PRIVATE_LIBS" ${ARGN})
  if(NOT ARG_EXPORT)
    set(ARG_EXPORT softshellTargets)
  endif()
  add_library(softshell_${name} ${ARG_SOURCES})
  # Consumers of the installed package get C++20 (the public headers use std::span and friends).
  target_compile_features(softshell_${name} PUBLIC cxx_std_20)
  if(EXISTS ${CMAKE_CURRENT_SOURCE_DIR}/include)
    target_include_directories(softshell_${name} PUBLIC
      $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
      $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
    install(DIRECTORY include/softshell DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  endif()
  target_link_libraries(softshell_${name} PUBLIC ${ARG_PUBLIC_LIBS} PRIVATE ${ARG_PRIVATE_LIBS})
  add_library(softshell::${name} ALIAS softshell_${name})
  set_target_properties(softshell_${name} PROPERTIES
    EXPORT_NAME ${name}
    OUTPUT_NAME softshell_${name}
    VERSION ${PROJECT_VERSION}
    SOVERSION ${PROJECT_VERSION_MAJOR}
    INSTALL_RPATH "$ORIGIN")  # the other softshell libraries sit beside it, wherever installed
  softshell_set_warnings(softshell_${name})
  install(TARGETS softshell_${name} EXPORT ${ARG_EXPORT}
    LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
    ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
    RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
    INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()
