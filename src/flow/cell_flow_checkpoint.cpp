#include "flow/cell_flow_checkpoint.hpp"

#include <fmt/format.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <type_traits>

#include "core/file_io.hpp"
#include "core/hash.hpp"

namespace trbc {
namespace {

constexpr std::string_view kMagic = "trbc-cell-flow-snapshot 3\n";

class Writer {
public:
    template <class T>
    void pod(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>);
        bytes_.append(reinterpret_cast<const char*>(&v), sizeof v);
    }
    void text(const std::string& s) {
        pod<std::uint64_t>(s.size());
        bytes_ += s;
    }
    void doubles(const std::vector<double>& v) {
        pod<std::uint64_t>(v.size());
        bytes_.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(double));
    }
    void matrix(const Vertices& X) {
        pod<std::uint64_t>(static_cast<std::uint64_t>(X.cols()));
        bytes_.append(reinterpret_cast<const char*>(X.data()), static_cast<std::size_t>(X.size()) * sizeof(double));
    }
    const std::string& bytes() const { return bytes_; }

private:
    std::string bytes_;
};

class Reader {
public:
    explicit Reader(std::string_view bytes) : bytes_(bytes) {}
    template <class T>
    T pod() {
        static_assert(std::is_trivially_copyable_v<T>);
        T v;
        std::memcpy(&v, take(sizeof v), sizeof v);
        return v;
    }
    std::string text() {
        const auto n = count(1);
        return std::string(take(n), n);
    }
    std::vector<double> doubles() {
        const auto n = count(sizeof(double));
        std::vector<double> v(n);
        std::memcpy(v.data(), take(n * sizeof(double)), n * sizeof(double));
        return v;
    }
    Vertices matrix() {
        const auto n = count(3 * sizeof(double));
        Vertices X(3, static_cast<Eigen::Index>(n));
        std::memcpy(X.data(), take(3 * n * sizeof(double)), 3 * n * sizeof(double));
        return X;
    }
    bool atEnd() const { return pos_ == bytes_.size(); }
    std::size_t remaining() const { return bytes_.size() - pos_; }

private:
    /// A length prefix, checked against what is left (elements of `size` bytes).
    std::size_t count(std::size_t size) {
        const auto n = pod<std::uint64_t>();
        if (n > (bytes_.size() - pos_) / size) throw std::runtime_error("length field beyond the end of the payload");
        return static_cast<std::size_t>(n);
    }
    const char* take(std::size_t n) {
        if (n > bytes_.size() - pos_) throw std::runtime_error("payload shorter than its fields");
        const char* p = bytes_.data() + pos_;
        pos_ += n;
        return p;
    }
    std::string_view bytes_;
    std::size_t pos_ = 0;
};

void writeResult(Writer& w, const CellFlowResult& r) {
    w.pod<std::uint8_t>(r.completed);
    w.pod<std::uint8_t>(r.stoppedEarly);
    w.text(r.message);
    w.doubles(r.times);
    w.pod<std::uint64_t>(r.frames.size());
    for (const Vertices& f : r.frames) w.matrix(f);
    w.doubles(r.areaDrift);
    w.doubles(r.volumeDrift);
    w.pod<std::uint64_t>(r.stepLog.size());
    for (const CellFlowStepRecord& s : r.stepLog) {
        for (double v : {s.t, s.dt, s.error, s.tension, s.fluxCorrection, s.areaDrift, s.volumeDrift, s.areaCorrection,
                         s.volumeCorrection})
            w.pod(v);
        w.pod(s.gmresIterations);
    }
    w.matrix(r.final);
    for (double v : {r.tReached, r.dtSmallest, r.dtLargest, r.maxAreaDrift, r.maxVolumeDrift, r.maxAreaCorrection,
                     r.maxVolumeCorrection, r.sumAreaCorrection, r.sumVolumeCorrection, r.maxFluxCorrection,
                     r.wallSeconds, r.resumedAt})
        w.pod(v);
    for (int v : {r.steps, r.rejectedSteps, r.failedSolves, r.maxGmresIterations, r.resumes}) w.pod(v);
    w.pod(r.gmresIterations);
    w.pod(r.sqrtIterations);
    w.pod(r.mobilityIterations);
    w.pod(r.maxSqrtIterations);
}

CellFlowResult readResult(Reader& rd) {
    CellFlowResult r;
    r.completed = rd.pod<std::uint8_t>() != 0;
    r.stoppedEarly = rd.pod<std::uint8_t>() != 0;
    r.message = rd.text();
    r.times = rd.doubles();
    const auto nf = rd.pod<std::uint64_t>();  // 0 when the run keeps no frames
    if (nf != r.times.size() && nf != 0) throw std::runtime_error("frame count differs from the frame times");
    for (std::uint64_t k = 0; k < nf; ++k) r.frames.push_back(rd.matrix());
    r.areaDrift = rd.doubles();
    r.volumeDrift = rd.doubles();
    const auto ns = rd.pod<std::uint64_t>();
    constexpr std::size_t kStepBytes = 9 * sizeof(double) + sizeof(int);
    if (ns > rd.remaining() / kStepBytes) throw std::runtime_error("step count beyond the end of the payload");
    r.stepLog.resize(ns);
    for (CellFlowStepRecord& s : r.stepLog) {
        for (double* v : {&s.t, &s.dt, &s.error, &s.tension, &s.fluxCorrection, &s.areaDrift, &s.volumeDrift,
                          &s.areaCorrection, &s.volumeCorrection})
            *v = rd.pod<double>();
        s.gmresIterations = rd.pod<int>();
    }
    r.final = rd.matrix();
    for (double* v : {&r.tReached, &r.dtSmallest, &r.dtLargest, &r.maxAreaDrift, &r.maxVolumeDrift,
                      &r.maxAreaCorrection, &r.maxVolumeCorrection, &r.sumAreaCorrection, &r.sumVolumeCorrection,
                      &r.maxFluxCorrection, &r.wallSeconds, &r.resumedAt})
        *v = rd.pod<double>();
    for (int* v : {&r.steps, &r.rejectedSteps, &r.failedSolves, &r.maxGmresIterations, &r.resumes}) *v = rd.pod<int>();
    r.gmresIterations = rd.pod<long>();
    r.sqrtIterations = rd.pod<long>();
    r.mobilityIterations = rd.pod<long>();
    r.maxSqrtIterations = rd.pod<int>();
    return r;
}

}  // namespace

void writeCellFlowSnapshot(const std::filesystem::path& file, const CellFlowSnapshot& s, std::uint64_t fingerprint) {
    Writer w;
    const CellFlowState& st = s.state;
    for (const Vertices* X : {&st.steps.X, &st.steps.Xprev, &st.steps.Xprev2}) w.matrix(*X);
    for (double v : {st.tension, st.steps.hPrev, st.steps.hPrev2, st.t, st.dt}) w.pod(v);
    w.pod(st.steps.accepted);
    w.pod(st.nextFrame);
    w.pod(st.framesChecked);
    w.doubles(s.environmentRecords);
    writeResult(w, s.result);
    const std::string& payload = w.bytes();
    Writer head;
    head.pod(fingerprint);
    head.pod<std::uint64_t>(payload.size());
    head.pod(fnv1a(payload));
    if (!file.parent_path().empty()) std::filesystem::create_directories(file.parent_path());
    writeFileAtomically(file, std::string(kMagic) + head.bytes() + payload);
}

std::optional<CellFlowSnapshot> readCellFlowSnapshot(const std::filesystem::path& file, std::uint64_t fingerprint,
                                                     std::string& why) {
    std::ifstream in(file, std::ios::binary);
    if (!in) {
        why = "no snapshot";
        return std::nullopt;
    }
    std::ostringstream buffer;
    buffer << in.rdbuf();
    const std::string bytes = buffer.str();
    const std::size_t headSize = kMagic.size() + 3 * sizeof(std::uint64_t);
    if (bytes.size() < headSize || std::string_view(bytes).substr(0, kMagic.size()) != kMagic) {
        why = "not a trbc cell-flow snapshot (wrong header)";
        return std::nullopt;
    }
    Reader head(std::string_view(bytes).substr(kMagic.size(), headSize - kMagic.size()));
    const auto tag = head.pod<std::uint64_t>(), size = head.pod<std::uint64_t>(), sum = head.pod<std::uint64_t>();
    const std::string_view payload = std::string_view(bytes).substr(headSize);
    if (tag != fingerprint) {
        why = fmt::format("a snapshot of another run (fingerprint {:016x}, this run {:016x})", tag, fingerprint);
        return std::nullopt;
    }
    if (payload.size() != size || fnv1a(payload) != sum) {
        why = fmt::format("damaged snapshot ({} payload bytes, {} expected, checksum {})", payload.size(), size,
                          fnv1a(payload) == sum ? "matches" : "differs");
        return std::nullopt;
    }
    try {
        Reader rd(payload);
        CellFlowSnapshot s;
        CellFlowState& st = s.state;
        for (Vertices* X : {&st.steps.X, &st.steps.Xprev, &st.steps.Xprev2}) *X = rd.matrix();
        for (double* v : {&st.tension, &st.steps.hPrev, &st.steps.hPrev2, &st.t, &st.dt}) *v = rd.pod<double>();
        st.steps.accepted = rd.pod<int>();
        st.nextFrame = rd.pod<std::uint64_t>();
        st.framesChecked = rd.pod<std::uint64_t>();
        s.environmentRecords = rd.doubles();
        s.result = readResult(rd);
        if (!rd.atEnd()) throw std::runtime_error("bytes after the last field");
        return s;
    } catch (const std::exception& e) {
        why = std::string("damaged snapshot: ") + e.what();
        return std::nullopt;
    }
}

}  // namespace trbc
