// Simulation::saveState / restoreState: the state between frames, for resuming a run.
#include "sim/sim.h"

#include <cstdint>
#include <cstring>
#include <istream>
#include <ostream>
#include <sstream>
#include <string>

namespace viscoscope::sim {

namespace {

constexpr char kMagic[4] = {'V', 'S', 'S', 'T'};
constexpr uint32_t kVersion = 1;
constexpr uint64_t kMaxRandomText = 1 << 16;  // std::mt19937_64 writes 313 numbers, a few kB

template <class T>
void put(std::ostream& out, const T& value) {
    out.write(reinterpret_cast<const char*>(&value), sizeof value);
}

void putDoubles(std::ostream& out, const double* values, size_t count) {
    out.write(reinterpret_cast<const char*>(values), std::streamsize(count * sizeof(double)));
}

// Reads what put/putDoubles wrote; a short read is a truncated file.
class Reader {
public:
    explicit Reader(std::istream& in) : in_(in) {}
    template <class T>
    T get() {
        T value{};
        read(&value, sizeof value);
        return value;
    }
    void doubles(double* values, size_t count) { read(values, count * sizeof(double)); }

private:
    void read(void* data, size_t bytes) {
        if (!in_.read(static_cast<char*>(data), std::streamsize(bytes)))
            throw InputError("saved simulation state: truncated");
    }
    std::istream& in_;
};

}  // namespace

template <class Self, class Visit>
void Simulation::forEachCarriedField(Self& self, Visit&& visit) {
    // The solve starts from its last pressure and stresses; surface tension and a shear-dependent
    // law's viscosities are read again before they are recomputed (the time step, the pressure
    // the frame files report). The velocity is rebuilt from the particles at the next step; it is
    // carried so that fields() and velocityAt() read after restoring are the saved run's.
    visit(self.state_.pressure);
    for (int a = 0; a < 3; ++a) {
        visit(self.state_.velocity[a]);
        visit(self.state_.normalStress[a]);
        visit(self.state_.shearStress[a]);
        visit(self.edgeViscosity_[a]);
    }
    visit(self.laplacePressure_);
    visit(self.cellViscosity_);
}

void Simulation::saveState(std::ostream& out) const {
    out.write(kMagic, 4);
    put(out, kVersion);
    put(out, int32_t(frame_));
    put(out, time_);
    put(out, emitterDebt_);
    put(out, uint8_t(volumeTarget_.has_value()));
    put(out, volumeTarget_.value_or(0.0));
    std::ostringstream random;
    random << random_;
    put(out, uint64_t(random.str().size()));
    out << random.str();

    put(out, uint64_t(particles_.position.size()));
    for (size_t p = 0; p < particles_.position.size(); ++p) {
        putDoubles(out, particles_.position[p].data(), 3);
        putDoubles(out, particles_.velocity[p].data(), 3);
        putDoubles(out, particles_.affine[p].data(), 9);
    }
    forEachCarriedField(*this, [&](const Field& field) {
        put(out, uint64_t(field.values.size()));
        putDoubles(out, field.values.data(), field.values.size());
    });
    if (!out) throw std::runtime_error("cannot write the simulation state");
}

void Simulation::restoreState(std::istream& in) {
    char magic[4];
    if (!in.read(magic, 4) || std::memcmp(magic, kMagic, 4) != 0)
        throw InputError("not a saved simulation state");
    Reader read(in);
    if (read.get<uint32_t>() != kVersion) throw InputError("saved simulation state: another version");
    // Read into a copy first, so that a state that does not fit leaves this simulation as it was.
    const int frame = read.get<int32_t>();
    const double time = read.get<double>(), emitterDebt = read.get<double>();
    const bool hasVolumeTarget = read.get<uint8_t>() != 0;
    const double volumeTarget = read.get<double>();
    const uint64_t randomLength = read.get<uint64_t>();
    if (randomLength > kMaxRandomText) throw InputError("saved simulation state: damaged");
    std::string randomText(randomLength, '\0');
    if (!in.read(randomText.data(), std::streamsize(randomText.size())))
        throw InputError("saved simulation state: truncated");
    std::mt19937_64 random;
    if (!(std::istringstream(randomText) >> random)) throw InputError("saved simulation state: damaged");

    // One particle at a time, so that a damaged count runs into the file's end, not out of memory.
    Particles particles;
    const uint64_t count = read.get<uint64_t>();
    for (uint64_t p = 0; p < count; ++p) {
        Vec3 position, velocity;
        Eigen::Matrix3d affine;
        read.doubles(position.data(), 3);
        read.doubles(velocity.data(), 3);
        read.doubles(affine.data(), 9);
        particles.position.push_back(position);
        particles.velocity.push_back(velocity);
        particles.affine.push_back(affine);
    }
    std::vector<std::vector<double>> fields;
    forEachCarriedField(*this, [&](const Field& field) {
        if (read.get<uint64_t>() != field.values.size())
            throw InputError("saved simulation state: made on another grid");
        fields.emplace_back(field.values.size());
        read.doubles(fields.back().data(), fields.back().size());
    });

    frame_ = frame;
    time_ = time;
    emitterDebt_ = emitterDebt;
    volumeTarget_ = hasVolumeTarget ? std::optional<double>(volumeTarget) : std::nullopt;
    random_ = random;
    particles_ = std::move(particles);
    size_t next = 0;
    forEachCarriedField(*this, [&](Field& field) { field.values = std::move(fields[next++]); });
    // As advanceFrame leaves them at the end of a frame.
    fractionsPositions_.reset();
    computeFractions();
}

}  // namespace viscoscope::sim
