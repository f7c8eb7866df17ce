// The simulation folder that `simulate` writes and `synth` and `compare` read.
#pragma once

#include "cli/progress.h"
#include "scene/digest.h"
#include "scene/scene.h"

#include <filesystem>
#include <string>

namespace viscoscope::cli {

// "prefix_NNNNN.ext": the name of frame NNNNN's file (frame 0 is the initial state).
std::string frameName(const char* prefix, int frame, const char* ext);

// Runs `scene` and writes its per-frame files (surface/surface.h) into `dir` as each frame is
// reached, then DIR/simulation.json last, so that its presence marks a complete run. Progress events
// say "stage": "simulate". Returns kExitOk, or kExitCancelled within a solver iteration of a cancel
// request (the frames written so far stay). Throws InputError when `dir` cannot be created.
// Until the run completes, DIR/resume.state holds its state as of a recent frame (saved after the
// first frame, then every few seconds, and on a cancel that comes between frames); a run of the same
// scene into `dir` goes on from there bit for bit, and one of another scene starts over and first
// removes the frame files it finds.
// A completed run of the same scene by the same engine build, its frame files all there, is kept as
// it is: running it again would give the same bits.
int simulateIntoFolder(const Scene& scene, const std::filesystem::path& dir, const ProgressReporter& progress);

}  // namespace viscoscope::cli
