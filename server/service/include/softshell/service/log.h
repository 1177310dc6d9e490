#pragma once
/// \file
/// \brief The server layers log through the SDK's `Logger` (softshell/log.h); these names keep the
/// `service::` spelling the server's options use.

#include "softshell/log.h"

namespace softshell::service {

using softshell::LogLevel;
using softshell::LogSink;
using softshell::Logger;
using softshell::parse_log_level;
using softshell::stderr_log_sink;
using softshell::to_string;

}  // namespace softshell::service
