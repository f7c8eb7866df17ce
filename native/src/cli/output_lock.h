// An output folder belongs to the run writing it. Two runs on one folder would each resume from
// the other's half-written state: the second would store the first's failed evaluations and
// answer differently, exit 0 (issue 67's probe).
#pragma once

#include <filesystem>

namespace viscoscope::cli {

class OutputFolderLock {
public:
    // Creates `dir` if needed and takes DIR/.viscoscope.lock (an flock, which the kernel releases
    // when the process ends, however it ends). Throws InputError naming the process that holds it.
    OutputFolderLock(const std::filesystem::path& dir, const char* command);
    ~OutputFolderLock();
    OutputFolderLock(const OutputFolderLock&) = delete;
    OutputFolderLock& operator=(const OutputFolderLock&) = delete;

private:
    int fd_ = -1;
};

}  // namespace viscoscope::cli
