// What the camera can see of a scene: the opaque solids' depth, and where liquid can be in view.
#include "observe/observe.h"

#include "sim/solid_field.h"
#include "surface/surface.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace viscoscope {

namespace {

constexpr double kNearPlane = 1e-4;  // as the rasterizer's: nothing is seen closer to the lens

// Per pixel centre, the camera-frame direction of its ray scaled to unit depth (z = 1), with the
// lens distortion undone.
std::vector<Eigen::Vector3d> pixelRays(const PinholeCamera& camera) {
    std::vector<cv::Point2d> pixels, normalized;
    pixels.reserve(size_t(camera.width) * camera.height);
    for (int row = 0; row < camera.height; ++row)
        for (int col = 0; col < camera.width; ++col) pixels.emplace_back(col, row);
    cv::Matx33d K;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) K(i, j) = camera.K(i, j);
    std::vector<double> distortion(camera.distortion.data(), camera.distortion.data() + 5);
    cv::undistortPoints(pixels, normalized, K, distortion);
    std::vector<Eigen::Vector3d> rays(normalized.size());
    for (size_t i = 0; i < rays.size(); ++i) rays[i] = {normalized[i].x, normalized[i].y, 1.0};
    return rays;
}

// The camera depths [enter, exit] over which a ray from `origin` along `direction` (per unit depth)
// crosses the box; enter > exit when it misses.
std::pair<double, double> boxSpan(const Vec3& origin, const Vec3& direction, const Vec3& lo, const Vec3& hi) {
    double enter = kNearPlane, exit = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
        if (std::abs(direction[a]) < 1e-300) {
            if (origin[a] < lo[a] || origin[a] > hi[a]) return {1, 0};
            continue;
        }
        double t0 = (lo[a] - origin[a]) / direction[a], t1 = (hi[a] - origin[a]) / direction[a];
        if (t0 > t1) std::swap(t0, t1);
        enter = std::max(enter, t0);
        exit = std::min(exit, t1);
    }
    return {enter, exit};
}

// Whether the ray reaches a point inside the domain and outside every solid before depth `end`:
// sphere tracing, which steps through solids by their distance and stops at the first free point.
bool reachesLiquidSpace(const sim::SolidField& solids, const Vec3& origin, const Vec3& direction, double enter,
                        double end, double cell) {
    const double speed = direction.norm();  // metres per unit of depth
    const double free = 1e-3 * cell, minStep = 0.1 * cell;
    for (double z = enter; z <= end; ) {
        const double d = solids.distance(origin + z * direction);
        if (d > free) return true;
        z += std::max(-d, minStep) / speed;
    }
    return false;
}

}  // namespace

SceneVisibility sceneVisibility(const Scene& scene, const PinholeCamera& camera) {
    SceneVisibility view;
    view.depthTolerance = surface::surfaceVoxelSize(scene.surfaceSmoothing());
    view.occluderDepth = cv::Mat1f(camera.height, camera.width, std::numeric_limits<float>::infinity());
    const std::vector<Eigen::Vector3d> rays = pixelRays(camera);
    const Eigen::Matrix3d toWorld = camera.R.transpose();
    const Vec3 centre = -toWorld * camera.t;
    for (size_t i = 0; i < scene.solids.size(); ++i) {
        if (!scene.isOpaque(i)) continue;
        if (const auto* ground = std::get_if<GroundSolid>(&scene.solids[i])) {
            // A plane has no finite mesh: its depth is where each ray meets it.
            for (int row = 0; row < camera.height; ++row)
                for (int col = 0; col < camera.width; ++col) {
                    const Vec3 direction = toWorld * rays[size_t(row) * camera.width + col];
                    const double depth = (ground->height - centre.z()) / direction.z();
                    if (std::isfinite(depth) && depth > kNearPlane)
                        view.occluderDepth(row, col) = std::min(view.occluderDepth(row, col), float(depth));
                }
            continue;
        }
        const TriangleMesh boundary = surface::solidBoundary(scene.solids[i]);
        view.occluderDepth = cv::min(view.occluderDepth, nearestDepth(boundary.vertices, boundary.triangles, camera));
    }

    const sim::SolidField solids(scene.solids, sim::sceneGrid(scene));
    view.liquidCanShow = cv::Mat1b(camera.height, camera.width, uchar(0));
    const double cell = scene.cellSize();
    for (int row = 0; row < camera.height; ++row)
        for (int col = 0; col < camera.width; ++col) {
            const Vec3 direction = toWorld * rays[size_t(row) * camera.width + col];
            const auto [enter, exit] = boxSpan(centre, direction, scene.domain.min, scene.domain.max);
            const double end = std::min(exit, double(view.occluderDepth(row, col)));
            if (enter <= end && reachesLiquidSpace(solids, centre, direction, enter, end, cell))
                view.liquidCanShow(row, col) = 255;
        }
    return view;
}

ComparedRegion comparedRegion(const cv::Mat1b& compared, const SceneVisibility& view, const cv::Mat1b& initialLiquid) {
    ComparedRegion region;
    region.compared = compared.empty() ? cv::Mat1b(view.liquidCanShow.size(), uchar(255)) : compared.clone();
    const cv::Mat1b unseeable = (region.compared != 0) & (view.liquidCanShow == 0);
    region.neverVisible = cv::countNonZero(unseeable);
    region.compared.setTo(0, unseeable);
    if (!initialLiquid.empty()) {
        cv::Mat1b held;
        cv::dilate(initialLiquid, held, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(5, 5)));
        held &= region.compared != 0;
        region.inBackground = cv::countNonZero(held);
        region.compared.setTo(0, held);
    }
    return region;
}

bool backgroundFromFootage(const ReferenceManifest& reference) {
    if (!reference.parameters.is_object() || !reference.parameters.contains("background")) return false;
    const nlohmann::json& background = reference.parameters["background"];
    return background == "clean_plate_frame" || background == "leading_frames";
}

double liquidOutOfViewShare(const std::vector<cv::Mat1b>& masks, const cv::Mat1b& compared,
                            const SceneVisibility& view) {
    double outside = 0, all = 0;
    for (const cv::Mat1b& mask : masks) {
        if (mask.empty()) continue;
        const cv::Mat1b liquid = compared.empty() ? mask != 0 : (mask != 0) & (compared != 0);
        all += cv::countNonZero(liquid);
        outside += cv::countNonZero(liquid & (view.liquidCanShow == 0));
    }
    return all > 0 ? outside / all : 0.0;
}

}  // namespace viscoscope
