// The screen-space objective (Takahashi & Lin 2019, eq. 9), IoU, the difference picture and the
// scalar-track terms.
#include "observe/observe.h"

#include "scene/scene.h"

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>

namespace viscoscope {

namespace {

void requireSameSize(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared) {
    if (simulated.size() != reference.size() || (!compared.empty() && compared.size() != reference.size()))
        throw InputError("silhouettes differ in size: simulated " + std::to_string(simulated.cols) + "x" +
                         std::to_string(simulated.rows) + ", reference " + std::to_string(reference.cols) + "x" +
                         std::to_string(reference.rows) +
                         (compared.empty() ? "" : ", exclusion " + std::to_string(compared.cols) + "x" +
                                                      std::to_string(compared.rows)));
}

// Counts pixels where `predicate(simulatedInside, referenceInside)` holds, over compared pixels.
template <typename Predicate>
long long countPixels(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared,
                      Predicate predicate) {
    long long count = 0;
    for (int row = 0; row < reference.rows; ++row) {
        const uchar* g = simulated.ptr(row);
        const uchar* gHat = reference.ptr(row);
        const uchar* c = compared.empty() ? nullptr : compared.ptr(row);
        for (int col = 0; col < reference.cols; ++col)
            if ((c == nullptr || c[col] != 0) && predicate(g[col] != 0, gHat[col] != 0)) ++count;
    }
    return count;
}

// The outlet (the centre of the first holed cup's underside) and the ground's height below it.
struct Outlet {
    Eigen::Vector3d position;
    double ground = 0;
};
std::optional<Outlet> findOutlet(const Scene& scene) {
    const std::optional<double> ground = groundHeight(scene);
    const CupSolid* cup = firstHoledCup(scene);
    if (!ground || !cup || cup->position.z() <= *ground) return std::nullopt;
    return Outlet{cup->position, *ground};
}

}  // namespace

SilhouetteComparison parseSilhouetteComparison(const std::string& name, const std::string& where) {
    if (name == "pixels") return SilhouetteComparison::kPixels;
    if (name == "row_widths") return SilhouetteComparison::kRowWidths;
    throw InputError(where + ": \"" + name + "\" is not \"pixels\" or \"row_widths\"");
}

std::string silhouetteComparisonName(SilhouetteComparison comparison) {
    return comparison == SilhouetteComparison::kPixels ? "pixels" : "row_widths";
}

double frameObjective(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared,
                      SilhouetteComparison comparison) {
    requireSameSize(simulated, reference, compared);
    const double pixelCount = static_cast<double>(reference.total());
    if (comparison == SilhouetteComparison::kPixels) {
        // Masks are binary, so (g − ĝ)² is 1 exactly where they disagree.
        const long long disagreeing = countPixels(simulated, reference, compared, [](bool g, bool r) { return g != r; });
        return disagreeing / (2.0 * pixelCount);
    }
    long long widthDifferences = 0;
    for (int row = 0; row < reference.rows; ++row) {
        const uchar* g = simulated.ptr(row);
        const uchar* gHat = reference.ptr(row);
        const uchar* c = compared.empty() ? nullptr : compared.ptr(row);
        long long difference = 0;
        for (int col = 0; col < reference.cols; ++col)
            if (c == nullptr || c[col] != 0) difference += (g[col] != 0) - (gHat[col] != 0);
        widthDifferences += std::abs(difference);
    }
    return widthDifferences / (2.0 * pixelCount);
}

double intersectionOverUnion(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared) {
    requireSameSize(simulated, reference, compared);
    const long long both = countPixels(simulated, reference, compared, [](bool g, bool r) { return g && r; });
    const long long either = countPixels(simulated, reference, compared, [](bool g, bool r) { return g || r; });
    return either == 0 ? 1.0 : static_cast<double>(both) / static_cast<double>(either);
}

cv::Mat3b differenceImage(const cv::Mat1b& simulated, const cv::Mat1b& reference, const cv::Mat1b& compared) {
    requireSameSize(simulated, reference, compared);
    const cv::Vec3b agreeInside(200, 200, 200), agreeOutside(40, 40, 40);
    const cv::Vec3b falsePositive(0, 140, 255), falseNegative(255, 120, 0);  // BGR: orange, blue
    cv::Mat3b picture(reference.size());
    for (int row = 0; row < reference.rows; ++row) {
        for (int col = 0; col < reference.cols; ++col) {
            const bool g = simulated(row, col) != 0, r = reference(row, col) != 0;
            cv::Vec3b colour = g == r ? (g ? agreeInside : agreeOutside) : (g ? falsePositive : falseNegative);
            if (!compared.empty() && compared(row, col) == 0) colour /= 3;
            picture(row, col) = colour;
        }
    }
    return picture;
}

double normalizedSquaredError(const std::vector<double>& simulated, const std::vector<double>& reference) {
    if (simulated.size() != reference.size())
        throw InputError("scalar track: simulated and reference have " + std::to_string(simulated.size()) + " and " +
                         std::to_string(reference.size()) + " samples");
    double squaredError = 0, squaredReference = 0;
    for (size_t i = 0; i < reference.size(); ++i) {
        squaredError += (simulated[i] - reference[i]) * (simulated[i] - reference[i]);
        squaredReference += reference[i] * reference[i];
    }
    if (!(squaredReference > 0)) throw InputError("scalar track: the reference track is all zero");
    return squaredError / squaredReference;
}

double outletHeight(const Scene& scene) {
    const std::optional<Outlet> outlet = findOutlet(scene);
    return outlet ? outlet->position.z() - outlet->ground : 0.0;
}

void requireGroundBandBelowOutlet(const Scene& scene, double band, const std::string& where) {
    if (!std::isfinite(band) || band < 0) throw InputError(where + ": must be a finite number ≥ 0 (m)");
    const double fall = outletHeight(scene);
    if (fall > 0 && band >= fall) {
        char height[32];
        std::snprintf(height, sizeof height, "%.3g", fall);
        throw InputError(where + ": must be below the outlet, " + height + " m above the ground");
    }
}

cv::Mat1b excludeGroundBand(const cv::Mat1b& compared, const PinholeCamera& camera, const Scene& scene, double band) {
    const std::optional<Outlet> outlet = findOutlet(scene);
    if (!(band > 0) || !outlet) return compared;
    Eigen::Vector3d onGround = outlet->position, bandTop = outlet->position;
    onGround.z() = outlet->ground;
    bandTop.z() = outlet->ground + band;
    if (toCameraFrame(camera, onGround).z() <= 0 || toCameraFrame(camera, bandTop).z() <= 0) return compared;
    const double groundRow = project(camera, onGround).y(), topRow = project(camera, bandTop).y();
    cv::Mat1b result = compared.empty() ? cv::Mat1b(camera.height, camera.width, uchar(255)) : compared.clone();
    for (int row = 0; row < result.rows; ++row)
        if ((groundRow > topRow && row > topRow) || (groundRow < topRow && row < topRow))  // row centres at integers
            result.row(row).setTo(0);
    return result;
}

double totalObjective(const std::vector<ObjectiveTerm>& terms) {
    double total = 0;
    for (const ObjectiveTerm& term : terms) total += term.weight * term.value;
    return total;
}

}  // namespace viscoscope
