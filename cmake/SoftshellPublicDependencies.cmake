# The public dependencies: their headers appear in softshell's public headers (Eigen, Bullet) or
# their symbols in its interface (Threads). This file is installed next to softshellConfig.cmake,
# where softshellConfig.cmake uses it for Bullet (only for softshell::bullet).
include_guard(GLOBAL)

# Eigen (dense/sparse linear algebra; public in the SDK headers).
if(NOT TARGET Eigen3::Eigen)
  find_package(Eigen3 3.3 REQUIRED CONFIG)
endif()

find_package(Threads REQUIRED)

# Bullet (single precision, Debian's default build), only for plugin_bullet.
if(SOFTSHELL_BUILD_BULLET OR SOFTSHELL_WANT_BULLET)
  if(NOT TARGET softshell_dep::bullet)
    find_package(Bullet 3.0 REQUIRED)
    set(_softshell_bullet_libs "")
    foreach(_lib BulletDynamics BulletCollision LinearMath)
      find_library(SOFTSHELL_BULLET_${_lib} ${_lib} REQUIRED)
      list(APPEND _softshell_bullet_libs "${SOFTSHELL_BULLET_${_lib}}")
    endforeach()
    find_path(SOFTSHELL_BULLET_INCLUDE_DIR btBulletDynamicsCommon.h PATH_SUFFIXES bullet REQUIRED)
    add_library(softshell_dep::bullet INTERFACE IMPORTED)
    set_target_properties(softshell_dep::bullet PROPERTIES
      INTERFACE_INCLUDE_DIRECTORIES "${SOFTSHELL_BULLET_INCLUDE_DIR}"
      INTERFACE_LINK_LIBRARIES "${_softshell_bullet_libs}")
  endif()
endif()
