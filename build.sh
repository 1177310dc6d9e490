#!/usr/bin/env bash
# softshell's one entry point for building: installs what is missing (Debian packages), configures,
# builds and runs.
#
#   ./build.sh demo [demo options]   build and run softshell-demo on the embedded server
#   ./build.sh test                  build everything and run every test (ctest)
#   ./build.sh build                 only build
#   ./build.sh deps                  only install the Debian packages
#
# Environment: BUILD_DIR (default: build), BUILD_TYPE (default: RelWithDebInfo), JOBS (default:
# the number of cores), CMAKE_ARGS (extra cmake arguments), TARGETS (build only these targets,
# space-separated; default all), EXTRA_PACKAGES (more Debian packages to install, e.g. clang),
# SOFTSHELL_NO_APT=1 to skip apt-get, SOFTSHELL_WEB_TESTS=0 to skip the browser client's tests (and
# their Node.js, Chromium and npm packages), SOFTSHELL_WEB_TESTS_REQUIRED=1 to fail when their npm
# packages cannot be installed (CI), SOFTSHELL_NGINX_TEST=0 not to install nginx (for the nginx proxy test).
set -euo pipefail
cd "$(dirname "$0")"

PACKAGES=(
  g++ cmake ninja-build pkg-config git ca-certificates
  libeigen3-dev libosd-dev libsuitesparse-dev libbullet-dev
  libcpp-httplib-dev nlohmann-json3-dev libssl-dev libstb-dev
  libgtest-dev libgmock-dev libopenblas0-pthread libcli11-dev curl
  libsqlite3-dev
)

# Optional: only tests/http/nginx_proxy_test.cpp needs nginx (it is skipped without it), so a
# failed install is reported, not fatal. SOFTSHELL_NGINX_TEST=0 leaves it out.
install_test_deps() {
  [ "${SOFTSHELL_NGINX_TEST:-1}" = 0 ] && return 0
  # In a subshell: where it cannot be installed (no root, no sudo, no network) the build goes on.
  (apt_install nginx) || echo "build.sh: nginx could not be installed; the nginx proxy test is skipped" >&2
}

install_deps() {
  # shellcheck disable=SC2206
  apt_install "${PACKAGES[@]}" ${EXTRA_PACKAGES:-}
}

apt_install() {
  [ "${SOFTSHELL_NO_APT:-0}" = 1 ] && return 0
  local missing=()
  local wanted=("$@")
  for p in "${wanted[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "build.sh: installing ${missing[*]}" >&2
  local sudo=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null || { echo "build.sh: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
    sudo="sudo"
  fi
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

# The web client's tests (tests/browser, label `browser`) need Node.js, npm and Chromium (Debian's,
# when missing; a newer Node already on the machine is kept) and web/'s npm packages, exactly as
# web/package-lock.json pins them. SOFTSHELL_WEB_TESTS=0 skips all of it.
install_web_deps() {
  [ "${SOFTSHELL_WEB_TESTS:-1}" = 0 ] && return 0
  local want=()
  command -v node >/dev/null || want+=(nodejs)
  command -v npm >/dev/null || want+=(npm)
  [ -x /usr/bin/chromium ] || want+=(chromium)
  [ ${#want[@]} -eq 0 ] || apt_install "${want[@]}"
  command -v npm >/dev/null || { echo "build.sh: the web tests need npm (or set SOFTSHELL_WEB_TESTS=0)" >&2; exit 1; }
  # npm ci only when the lockfile changed since the last install. Where the npm registry cannot be
  # reached (no network, or a TLS proxy whose certificate npm does not trust), everything else is
  # still built and tested and the browser suite is reported as skipped; CI sets
  # SOFTSHELL_WEB_TESTS_REQUIRED=1, which makes it an error.
  if [ ! -f web/node_modules/.package-lock.json ] || [ web/package-lock.json -nt web/node_modules/.package-lock.json ]; then
    if ! (cd web && npm ci --no-audit --no-fund --loglevel=error); then
      if [ "${SOFTSHELL_WEB_TESTS_REQUIRED:-0}" = 1 ]; then
        echo "build.sh: npm ci failed in web/ (see above), and SOFTSHELL_WEB_TESTS_REQUIRED=1" >&2
        exit 1
      fi
      echo "build.sh: WARNING: npm ci failed in web/ (see above: is https://registry.npmjs.org reachable and its" >&2
      echo "  certificate trusted?). The browser tests will be reported as skipped; SOFTSHELL_WEB_TESTS=0 leaves them out." >&2
    fi
  fi
}

BUILD_DIR=${BUILD_DIR:-build}
JOBS=${JOBS:-$(nproc)}

configure() {
  local launcher=()
  command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  # shellcheck disable=SC2086
  local web=ON
  [ "${SOFTSHELL_WEB_TESTS:-1}" = 0 ] && web=OFF
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-RelWithDebInfo}" -DSOFTSHELL_WEB_TESTS=$web \
    "${launcher[@]}" ${CMAKE_ARGS:-} >/dev/null
}

cmd=${1:-help}
[ $# -gt 0 ] && shift
case "$cmd" in
  deps) install_deps; install_web_deps; install_test_deps ;;
  build) install_deps; configure; cmake --build "$BUILD_DIR" -j "$JOBS" ;;
  demo)
    install_deps; configure
    cmake --build "$BUILD_DIR" -j "$JOBS" --target softshell-demo
    "$BUILD_DIR/demo_headless/softshell-demo" "$@"
    ;;
  test)
    install_deps; install_web_deps; install_test_deps; configure
    # shellcheck disable=SC2086
    cmake --build "$BUILD_DIR" -j "$JOBS" ${TARGETS:+--target $TARGETS}
    ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" "$@"
    ;;
  *) sed -n '2,16p' "$0"; [ "$cmd" = help ] || exit 2 ;;
esac
