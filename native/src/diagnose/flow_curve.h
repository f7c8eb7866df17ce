// The diagnosis's answer as a rheologist reads it: the fitted law's flow curve τ(γ̇) over the shear
// rates its flow exercised, with the band of what its fit cannot tell apart, and against the job's
// rheometer where it names one. Private to the stage.
#pragma once

#include "diagnose/diagnose.h"

#include <nlohmann/json.hpp>

namespace viscoscope::diagnose {

// An RMS of log10 stress against the rheometer above this is warned of: the similarity-analysis
// method of Hamamichi et al. 2023 fits its liquids' rheometer curves within 0.05–0.14 (issue 88).
constexpr double kRheometerLogStressWarning = 0.15;

// `fit` of `model` (its job: the law and parameters) as diagnosis.json's "flow_curve": the model,
// the shear-rate range, points of γ̇, τ, η and τ's band (the least and greatest over the evaluations
// E cannot tell from θ*, or else over the corners of the parameters' intervals), and with
// `model.rheometer` the RMS of log10 τ against it over the range both cover. Null when the fit's
// flow has no shear-rate range (the thin film).
nlohmann::json flowCurve(const ModelFit& fit, const identify::Job& model);

}  // namespace viscoscope::diagnose
