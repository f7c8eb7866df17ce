// The effects diagnose knows, each a record made in a file of its own (effect.h), and what their
// files share.
#pragma once

#include "diagnose/effect.h"

namespace viscoscope::diagnose {

// A new parameter's start spreads this far in ln θ: nobody has fitted it yet.
constexpr double kNewLogSpread = 1.5;
// A parameter restarted near a fitted value (the base's, or a scene's guess) spreads this far.
constexpr double kWarmLogSpread = 0.5;

Effect shearThinning();  // shear_thinning.cpp
Effect yieldStress();    // yield_stress.cpp
Effect wallSlip();       // wall_slip.cpp
Effect sideWalls();      // side_walls.cpp

}  // namespace viscoscope::diagnose
