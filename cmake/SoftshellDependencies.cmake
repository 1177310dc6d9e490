# Third-party dependencies, all from Debian's packages (see README "Dependencies"), each an
# imported target: the public ones (SoftshellPublicDependencies.cmake, installed) and the private
# ones (SoftshellPrivateDependencies.cmake, installed only for static builds).
include_guard(GLOBAL)
include(${CMAKE_CURRENT_LIST_DIR}/SoftshellPublicDependencies.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/SoftshellPrivateDependencies.cmake)
