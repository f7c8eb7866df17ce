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
Effect herschelBulkley();  // herschel_bulkley.cpp

// Parameters and start curves the material laws share.
// A power law's K from the base's η* over the base's bounds of η (shear_thinning.cpp).
AddedParameter thinningConsistency(const BaseFit& base);
// The flow index n ≤ 1, thinning only (shear_thinning.cpp).
AddedParameter flowIndex();
// The curve of (K, n) that flows as the base fit at the base flow's shear rate γ̇_c, K = η* γ̇_c^(1−n),
// from n = 1 (the base's own flow) at s = 0 to a thin liquid at s = 1, the other parameters at their
// starts; none without the base flow's shear rate (shear_thinning.cpp).
StartCurve thinningRidge(const nlohmann::json& parameters, const BaseFit& base);
// τ_y within the bounds the liquid's hydrostatic stress and the base flow's viscous stress set
// (yield_stress.cpp).
AddedParameter yieldStressParameter(const BaseFit& base);

}  // namespace viscoscope::diagnose
