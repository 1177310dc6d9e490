#pragma once
// The scripted hands (paper Section 6.2): rays from a virtual hand pick points of the limit
// surface where a hand can reach the object; grabs drag them, a push presses one. Each phase
// starts from the rest shape, scales its loads from a probe so that it stays inside the linear
// model's range (linear_range.h), and ends by letting go (except the last, held at the end).

#include "context.h"

namespace softshell::demo {

/// Pulls the top of the object up and out, then lets go.
void grab_phase(Context& c);
/// Presses the side with a growing force, then lets go.
void push_phase(Context& c);
/// Lifts a point while turning its tangent plane, then lets go.
void twist_phase(Context& c);
/// One large pull (the grab's point, far) solved with both models, for the side-by-side picture;
/// then lets go. Outside the latencies and the range checks: the linear answer leaves the range on
/// purpose.
void large_pull_phase(Context& c);
/// Two hands pull two points apart and hold them (the final state).
void two_hands_phase(Context& c);

}  // namespace softshell::demo
