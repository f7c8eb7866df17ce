#include "scene/scene.h"

#include <atomic>

namespace viscoscope {

namespace {
std::atomic<bool> g_scaleLimitsWaived{false};
}  // namespace

void waiveScaleLimits() noexcept { g_scaleLimitsWaived.store(true, std::memory_order_relaxed); }
bool scaleLimitsWaived() noexcept { return g_scaleLimitsWaived.load(std::memory_order_relaxed); }

}  // namespace viscoscope
