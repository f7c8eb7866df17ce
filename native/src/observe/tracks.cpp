// Scalar tracks: observables over time, measured from masks or read from a lab's CSV.
#include "observe/observe.h"

#include "scene/scene.h"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>

namespace viscoscope {

namespace {

std::vector<std::string> splitCsvLine(const std::string& line) {
    std::vector<std::string> fields;
    std::stringstream stream(line);
    std::string field;
    while (std::getline(stream, field, ',')) fields.push_back(field);
    if (!line.empty() && line.back() == ',') fields.emplace_back();
    return fields;
}

std::string trimmed(std::string text) {
    const auto isSpace = [](unsigned char c) { return std::isspace(c) != 0; };
    text.erase(text.begin(), std::find_if_not(text.begin(), text.end(), isSpace));
    text.erase(std::find_if_not(text.rbegin(), text.rend(), isSpace).base(), text.end());
    return text;
}

double parseCsvNumber(const std::string& field, const std::string& where) {
    const std::string text = trimmed(field);
    size_t used = 0;
    double value = 0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        used = 0;
    }
    if (text.empty() || used != text.size() || !std::isfinite(value))
        throw InputError(where + ": \"" + text + "\" is not a finite number");
    return value;
}

}  // namespace

ScalarTrack loadScalarTrackCsv(const std::filesystem::path& file, const std::string& firstColumn) {
    std::ifstream stream(file);
    if (!stream) throw InputError(file.string() + ": cannot open scalar-track CSV");
    std::string line;
    if (!std::getline(stream, line)) throw InputError(file.string() + ": empty file, expected a header line");
    std::vector<std::string> header = splitCsvLine(trimmed(line));
    for (std::string& name : header) name = trimmed(name);
    if (header.size() < 2 || header[0] != firstColumn)
        throw InputError(file.string() + ":1: header must start with \"" + firstColumn + "\" and name at least one value column");
    ScalarTrack track;
    track.columns.assign(header.begin() + 1, header.end());
    track.values.resize(track.columns.size());
    for (int lineNumber = 2; std::getline(stream, line); ++lineNumber) {
        if (trimmed(line).empty()) continue;
        const std::string where = file.string() + ":" + std::to_string(lineNumber);
        const std::vector<std::string> fields = splitCsvLine(trimmed(line));
        if (fields.size() != header.size())
            throw InputError(where + ": expected " + std::to_string(header.size()) + " fields, got " +
                             std::to_string(fields.size()));
        const double time = parseCsvNumber(fields[0], where);
        if (!track.time.empty() && time < track.time.back()) throw InputError(where + ": " + firstColumn + " goes backwards");
        track.time.push_back(time);
        for (size_t c = 0; c < track.columns.size(); ++c) track.values[c].push_back(parseCsvNumber(fields[c + 1], where));
    }
    if (track.time.empty()) throw InputError(file.string() + ": no data rows");
    return track;
}

void saveScalarTrackCsv(const ScalarTrack& track, const std::filesystem::path& file) {
    writeFileAtomically(file, [&](std::ostream& stream) {
        stream << "time_s";
        for (const std::string& column : track.columns) stream << "," << column;
        stream << "\n" << std::setprecision(10);
        for (size_t i = 0; i < track.time.size(); ++i) {
            stream << track.time[i];
            for (const std::vector<double>& column : track.values) stream << "," << column[i];
            stream << "\n";
        }
    });
}

namespace {

// The parameter interval [enter, exit] (exit < enter when empty) in which origin + s·unit, s ≥ 0,
// lies inside the image box [−0.5, W − 0.5] × [−0.5, H − 0.5] (slab method).
std::pair<double, double> rayInsideImage(const Eigen::Vector2d& origin, const Eigen::Vector2d& unit, cv::Size size) {
    double enter = 0, exit = std::numeric_limits<double>::infinity();
    const double upper[2] = {size.width - 0.5, size.height - 0.5};
    for (int axis = 0; axis < 2; ++axis) {
        if (unit[axis] == 0) {
            if (origin[axis] < -0.5 || origin[axis] > upper[axis]) return {1, 0};
            continue;
        }
        const double s0 = (-0.5 - origin[axis]) / unit[axis], s1 = (upper[axis] - origin[axis]) / unit[axis];
        enter = std::max(enter, std::min(s0, s1));
        exit = std::min(exit, std::max(s0, s1));
    }
    return {enter, exit};
}

}  // namespace

double frontAlongRay(const cv::Mat1b& mask, const ImageRay& ray) {
    const double length = ray.direction.norm();
    if (!(length > 0)) throw InputError("front ray: direction must be non-zero");
    const Eigen::Vector2d unit = ray.direction / length;
    const auto [enter, exit] = rayInsideImage(ray.origin, unit, mask.size());
    // Quarter-pixel steps visit every pixel the ray passes through.
    constexpr double kStep = 0.25;
    double front = 0;
    for (double s = enter; s <= exit; s += kStep) {
        const Eigen::Vector2d p = ray.origin + s * unit;
        const int col = std::clamp(static_cast<int>(std::lround(p.x())), 0, mask.cols - 1);
        const int row = std::clamp(static_cast<int>(std::lround(p.y())), 0, mask.rows - 1);
        if (mask(row, col) != 0) front = s;
    }
    return front;
}

double silhouetteArea(const cv::Mat1b& mask) { return static_cast<double>(cv::countNonZero(mask)); }

ScalarTrack tracksFromMasks(const ReferenceManifest& reference, const std::optional<ImageRay>& ray) {
    ScalarTrack track;
    if (ray) track.columns.push_back("front_px");
    track.columns.push_back("area_px");
    track.values.resize(track.columns.size());
    for (size_t i = 0; i < reference.frames.size(); ++i) {
        const cv::Mat1b mask = reference.mask(i);
        track.time.push_back(reference.times[i]);
        if (ray) track.values.front().push_back(frontAlongRay(mask, *ray));
        track.values.back().push_back(silhouetteArea(mask));
    }
    return track;
}

std::vector<double> sampleTrack(const ScalarTrack& track, size_t column, const std::vector<double>& times) {
    const std::vector<double>& values = track.values.at(column);
    std::vector<double> samples;
    samples.reserve(times.size());
    for (double t : times) {
        const auto after = std::upper_bound(track.time.begin(), track.time.end(), t);
        if (after == track.time.begin()) {
            samples.push_back(values.front());
        } else if (after == track.time.end()) {
            samples.push_back(values.back());
        } else {
            const size_t i = static_cast<size_t>(after - track.time.begin());
            const double t0 = track.time[i - 1], t1 = track.time[i];
            const double w = t1 > t0 ? (t - t0) / (t1 - t0) : 0;
            samples.push_back((1 - w) * values[i - 1] + w * values[i]);
        }
    }
    return samples;
}

}  // namespace viscoscope

namespace viscoscope {

namespace {
constexpr double kExtremePercentile = 0.995;

double percentile(std::vector<double> values, double q) {
    if (values.empty()) return 0;
    const size_t k = static_cast<size_t>(q * (values.size() - 1));
    std::nth_element(values.begin(), values.begin() + k, values.end());
    return values[k];
}

bool onGround(const Eigen::Vector3d& x, const GroundObservables& g) {
    return x.z() >= g.groundHeight - 1e-9 && x.z() <= g.groundHeight + g.band;
}
}  // namespace

double frontAlongGround(const std::vector<Eigen::Vector3d>& particles, const Eigen::Vector3d& origin,
                        const Eigen::Vector3d& direction, const GroundObservables& ground) {
    const Eigen::Vector3d d(direction.x(), direction.y(), 0);
    if (d.norm() == 0) throw InputError("front direction: must have a horizontal component");
    // Like frontAlongRay: only the liquid on a strip along the ray counts, `band` wide each side.
    const Eigen::Vector3d along = d.normalized(), across(-along.y(), along.x(), 0);
    std::vector<double> reach;
    for (const Eigen::Vector3d& x : particles)
        if (onGround(x, ground) && std::abs((x - origin).dot(across)) <= ground.band)
            reach.push_back((x - origin).dot(along));
    return std::max(0.0, percentile(std::move(reach), kExtremePercentile));
}

double puddleDiameter(const std::vector<Eigen::Vector3d>& particles, const Eigen::Vector3d& centre,
                      const GroundObservables& ground) {
    std::vector<double> radius;
    for (const Eigen::Vector3d& x : particles)
        if (onGround(x, ground)) radius.push_back(std::hypot(x.x() - centre.x(), x.y() - centre.y()));
    return 2 * percentile(std::move(radius), kExtremePercentile);
}

double drainedVolume(const std::vector<Eigen::Vector3d>& particles, double particleVolume, double height) {
    return particleVolume * static_cast<double>(std::count_if(
                                particles.begin(), particles.end(),
                                [&](const Eigen::Vector3d& x) { return x.z() < height; }));
}

}  // namespace viscoscope
