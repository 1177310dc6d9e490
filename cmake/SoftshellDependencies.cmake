# Third-party dependencies, all from Debian's packages (see README "Dependencies").
# Every dependency ends up as an imported target; this file is also installed next to
# softshellConfig.cmake so that find_package(softshell) recreates the same targets.
include_guard(GLOBAL)
include(CMakeFindDependencyMacro)

# Eigen (dense/sparse linear algebra; public in the SDK headers).
if(NOT TARGET Eigen3::Eigen)
  find_package(Eigen3 3.3 REQUIRED CONFIG)
endif()

# OpenSubdiv (Far refinement, Bfr limit evaluation). Debian's OpenSubdivConfig.cmake refers to
# static libraries the package does not ship, so the shared library is found directly.
if(NOT TARGET softshell_dep::opensubdiv)
  find_path(SOFTSHELL_OSD_INCLUDE_DIR opensubdiv/bfr/surface.h REQUIRED)
  find_library(SOFTSHELL_OSD_LIBRARY osdCPU REQUIRED)
  add_library(softshell_dep::opensubdiv UNKNOWN IMPORTED)
  set_target_properties(softshell_dep::opensubdiv PROPERTIES
    IMPORTED_LOCATION "${SOFTSHELL_OSD_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${SOFTSHELL_OSD_INCLUDE_DIR}")
endif()

# nlohmann/json: the JSON side of the wire codecs, so we do not hand-write a parser.
if(NOT TARGET nlohmann_json::nlohmann_json)
  find_package(nlohmann_json 3.10 REQUIRED CONFIG)
endif()

# OpenSSL's libcrypto: SHA-256 for content-addressed geometry ids.
if(NOT TARGET OpenSSL::Crypto)
  find_package(OpenSSL 1.1.1 REQUIRED COMPONENTS Crypto)
endif()

find_package(Threads REQUIRED)

# CHOLMOD (SuiteSparse 5.x ships no CMake package on Debian 12).
if(NOT TARGET softshell_dep::cholmod)
  find_path(SOFTSHELL_CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse REQUIRED)
  find_library(SOFTSHELL_CHOLMOD_LIBRARY cholmod REQUIRED)
  find_library(SOFTSHELL_SUITESPARSECONFIG_LIBRARY suitesparseconfig REQUIRED)
  add_library(softshell_dep::cholmod UNKNOWN IMPORTED)
  set_target_properties(softshell_dep::cholmod PROPERTIES
    IMPORTED_LOCATION "${SOFTSHELL_CHOLMOD_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${SOFTSHELL_CHOLMOD_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${SOFTSHELL_SUITESPARSECONFIG_LIBRARY}")
endif()

# cpp-httplib. Debian ships it split into httplib.h + libcpp-httplib.so, compiled with
# OpenSSL, zlib and brotli support; the same macros must be defined wherever the header
# is included, or the class layouts differ from the library's. CPPHTTPLIB_USE_POLL: without it
# cpp-httplib 0.11 waits with select(), which corrupts memory once a descriptor number reaches
# 1024 (upstream issue #754). Debian's library is built with poll() (its select_read calls
# poll; it imports no select), so the header is told the same; softshell's own connection loop
# (server/http/src/listener.cpp) uses poll() and epoll only.
if(NOT TARGET softshell_dep::httplib)
  find_path(SOFTSHELL_HTTPLIB_INCLUDE_DIR httplib.h REQUIRED)
  find_library(SOFTSHELL_HTTPLIB_LIBRARY cpp-httplib REQUIRED)
  add_library(softshell_dep::httplib UNKNOWN IMPORTED)
  set_target_properties(softshell_dep::httplib PROPERTIES
    IMPORTED_LOCATION "${SOFTSHELL_HTTPLIB_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${SOFTSHELL_HTTPLIB_INCLUDE_DIR}"
    INTERFACE_COMPILE_DEFINITIONS
      "CPPHTTPLIB_OPENSSL_SUPPORT;CPPHTTPLIB_ZLIB_SUPPORT;CPPHTTPLIB_BROTLI_SUPPORT;CPPHTTPLIB_USE_POLL"
    INTERFACE_LINK_LIBRARIES "OpenSSL::Crypto;Threads::Threads")
endif()

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
