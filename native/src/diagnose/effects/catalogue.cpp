// The effects diagnose tries, in the order it fits them.
#include "diagnose/diagnose.h"
#include "diagnose/effects/effects.h"

namespace viscoscope::diagnose {

const std::vector<Effect>& effects() {
    static const std::vector<Effect> catalogue{shearThinning(), yieldStress(), wallSlip(), sideWalls(), herschelBulkley()};
    return catalogue;
}

}  // namespace viscoscope::diagnose
