#pragma once
// The demo's shared-interaction phase (PROTOCOL.md version 2, holds and events): two users of
// different clients each hold a point of the object and move it along a path of their own, boxes
// rest on it through the Bullet bridge (its contacts and its floor are holds too), and a third
// client follows through the event stream and must end on the same state.

#include "context.h"

namespace softshell::demo {

/// Runs the phase (needs the grab phase's calibrated reach, `report.loads.grab`) and fills
/// `report.multi_user`.
void multi_user_phase(Context& c);

}  // namespace softshell::demo
