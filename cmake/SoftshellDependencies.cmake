# Third-party dependencies, all from Debian's packages (see README "Dependencies"), each an
# imported target: the public ones (SoftshellPublicDependencies.cmake, installed) and the private
# ones (SoftshellPrivateDependencies.cmake, installed only for static builds).
include_guard(GLOBAL)
include(${CMAKE_CURRENT_LIST_DIR}/SoftshellPublicDependencies.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/SoftshellPrivateDependencies.cmake)

# CLI11 (header-only): the command lines of softshell-server and softshell-demo (--opt=value and
# --opt value, --help, --version, validation, SOFTSHELL_* environment variables). Needed only to
# build those two programs, so it is here (this file is not installed), not among the private
# dependencies a static build's consumers find.
if(NOT TARGET CLI11::CLI11)
  find_package(CLI11 2.1 REQUIRED CONFIG)
endif()
