// The identify stage's face. Its parts: the optimizer (cma_es.h), the job (job.h), one evaluation
// and the pools it runs in (evaluation.h), E's profile near its best (profile.h), the search space
// (search_space.h) and the identification loop (identification.h), which the diagnosis stage
// (diagnose/diagnose.h) drives. The loop's own state (checkpoint, time budget, fields, alignment check, results)
// is private to the stage (search_state.h).
#pragma once

#include "identify/cma_es.h"
#include "identify/evaluation.h"
#include "identify/identification.h"
#include "identify/job.h"
#include "identify/profile.h"
#include "identify/search_space.h"
