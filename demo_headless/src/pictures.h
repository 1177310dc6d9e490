#pragma once
// The demo's pictures: what happened, drawn so a person can see it. The object at rest with its
// supports; each recorded moment (the Bullet boxes labelled by mass, the push with its force, the
// two hands with the points they hold) on the floor, with the rest shape as a ghost, displacements
// exaggerated (and labelled so) where they are too small to see, framed on the deformed bounds;
// one large pull with the linear and the nonlinear model side by side; the follower's view; the
// stresses.

#include <optional>

#include "context.h"
#include "softshell/stresses.h"

namespace softshell::demo {

class Follower;

/// Writes the PNGs into `options.out_dir` and lists them in `report.outputs`. `stresses`: of the
/// final state at the vertices of a level-`stress_level` tessellation, if the server has them.
void write_pictures(Context& c, const Follower* follower, const std::optional<StressField>& stresses, int stress_level);

}  // namespace softshell::demo
