#include "cli/output_lock.h"

#include "scene/scene.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <string>
#include <sys/file.h>
#include <unistd.h>

namespace viscoscope::cli {

OutputFolderLock::OutputFolderLock(const std::filesystem::path& dir, const char* command) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) throw InputError(dir.string() + ": cannot create output folder (" + ec.message() + ")");
    const std::filesystem::path file = dir / ".viscoscope.lock";
    fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw InputError(file.string() + ": cannot open (" + std::strerror(errno) + ")");
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
        char holder[256] = {};
        const ssize_t n = ::pread(fd_, holder, sizeof holder - 1, 0);
        ::close(fd_);
        fd_ = -1;
        std::string who = n > 0 ? std::string(holder, static_cast<size_t>(n)) : "another process";
        while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
        throw InputError(dir.string() + ": in use by " + who +
                         "; wait for it to end, or give another --out");
    }
    const std::string holder = "process " + std::to_string(::getpid()) + " (viscoscope " + command + ")\n";
    if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, holder.data(), holder.size(), 0) != static_cast<ssize_t>(holder.size()))
        throw InputError(file.string() + ": cannot write (" + std::strerror(errno) + ")");
}

OutputFolderLock::~OutputFolderLock() {
    if (fd_ >= 0) ::close(fd_);  // closing releases the flock
}

}  // namespace viscoscope::cli
