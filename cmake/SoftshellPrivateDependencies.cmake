# The private dependencies: used inside softshell's libraries only. A consumer of the installed
# shared libraries never needs their development files (they are link-time private and the
# public headers include none of theirs); this file is installed only for static builds, whose
# archives must be linked with them.
include_guard(GLOBAL)

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

# SQLite 3 (libsqlite3-dev): the service's persistent store (ServiceOptions::data_dir), through
# pkg-config since Debian ships no CMake package for it.
if(NOT TARGET PkgConfig::SQLITE3)
  find_package(PkgConfig REQUIRED)
  pkg_check_modules(SQLITE3 REQUIRED IMPORTED_TARGET sqlite3>=3.31)
endif()

# CHOLMOD (SuiteSparse 5.x ships no CMake package on Debian 12); only for the CHOLMOD backend
# (SOFTSHELL_SPARSE_CHOLESKY=cholmod, the default).
if(NOT SOFTSHELL_SPARSE_CHOLESKY STREQUAL "eigen" AND NOT TARGET softshell_dep::cholmod)
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
