#pragma once
// The checks of a shell's settings and the default name of its holds (shell_bridge.cpp's).

#include <string>

#include "softshell/bullet/shell_bridge.h"

namespace softshell::bullet {

/// Throws Exception(kInvalidArgument) naming the first setting out of its range.
void check_settings(const ShellSettings& s);
/// "bullet-" and 8 random hex digits: a name no other bridge picks by chance.
std::string random_hold_name();

}  // namespace softshell::bullet
