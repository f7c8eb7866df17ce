#include "scene/scene.h"

#include <atomic>
#include <string>

namespace viscoscope {

namespace {
std::atomic<bool> g_cancelRequested{false};
static_assert(std::atomic<bool>::is_always_lock_free, "raised from a signal handler");
}  // namespace

void requestCancel() noexcept { g_cancelRequested.store(true, std::memory_order_relaxed); }
void withdrawCancel() noexcept { g_cancelRequested.store(false, std::memory_order_relaxed); }
bool cancelRequested() noexcept { return g_cancelRequested.load(std::memory_order_relaxed); }

void throwIfCancelled(const char* what) {
    if (cancelRequested()) throw Cancelled(std::string(what) + " cancelled");
}

}  // namespace viscoscope
