#include "sampling/campaign_table.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "core/csv.hpp"
#include "core/error.hpp"

namespace trbc {

const std::string& campaignCsvHeader() {
    static const std::string h =
        "sample_id,cell_id,seed,v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,Fext_pN,"
        "D_um,hmin_um,hmax_um,D0_um,D1_um,tc_s,status,reason,wall_s";
    return h;
}

static std::string num(double x) { return std::isfinite(x) ? fmt::format("{:.17g}", x) : "nan"; }

std::string formatCampaignRow(const CampaignRow& r) {
    const CampaignPoint& q = r.point;
    return fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4f}", q.sampleId, q.cellId, r.seed,
                       num(q.p.v), num(q.p.mu), num(q.p.FvK), num(q.p.b2), num(q.p.etam), num(q.fext), num(r.D),
                       num(r.hmin), num(r.hmax), num(r.D0), num(r.D1), num(r.tc), csvField(r.status), csvField(csvSafe(r.reason)),
                       r.wallSeconds);
}

std::string csvSafe(std::string text) {
    for (char& c : text)
        if (c == ',' || c == '\n' || c == '\r') c = c == ',' ? ';' : ' ';
    return text;
}

namespace {

double parseDouble(const std::string& s, const std::string& where, const char* column) {
    if (s == "nan") return NAN;
    double x = 0.0;
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), x);
    if (ec != std::errc() || ptr != s.data() + s.size() || !std::isfinite(x))
        throw InputError(fmt::format("{}: column {}: '{}' is not a finite number", where, column, s));
    return x;
}

template <class Int>
Int parseInt(const std::string& s, const std::string& where, const char* column) {
    Int x = 0;
    const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), x);
    if (ec != std::errc() || ptr != s.data() + s.size())
        throw InputError(fmt::format("{}: column {}: '{}' is not an integer", where, column, s));
    return x;
}

}  // namespace

std::vector<CampaignRow> readCampaignCsv(const std::filesystem::path& path, bool dropTruncatedTail, bool* truncated) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(fmt::format("cannot open campaign table {}", path.string()));
    std::stringstream buf;
    buf << in.rdbuf();
    const std::string text = buf.str();
    if (truncated) *truncated = false;
    std::vector<CampaignRow> rows;
    std::size_t pos = 0;
    long lineNo = 0;
    bool headerSeen = false;
    while (pos < text.size()) {
        const std::size_t nl = text.find('\n', pos);
        ++lineNo;
        const std::string where = fmt::format("{}:{}", path.string(), lineNo);
        if (nl == std::string::npos && dropTruncatedTail) {
            if (truncated) *truncated = true;
            break;
        }
        const std::string line = text.substr(pos, nl == std::string::npos ? std::string::npos : nl - pos);
        pos = nl == std::string::npos ? text.size() : nl + 1;
        if (line.starts_with('#')) continue;  // the provenance line
        if (!headerSeen) {
            headerSeen = true;
            if (line != campaignCsvHeader())
                throw InputError(fmt::format("{}: not a campaign table header (expected '{}')", where, campaignCsvHeader()));
            continue;
        }
        if (line.empty()) continue;
        const auto records = parseCsvRecords(line);  // one line: csvSafe keeps line breaks out of the reason
        const auto f = records.empty() ? std::vector<std::string>{} : records[0];
        if (f.size() != 18) throw InputError(fmt::format("{}: {} fields, expected 18", where, f.size()));
        CampaignRow r;
        CampaignPoint& q = r.point;
        q.sampleId = parseInt<long>(f[0], where, "sample_id");
        q.cellId = parseInt<long>(f[1], where, "cell_id");
        r.seed = parseInt<std::uint64_t>(f[2], where, "seed");
        const char* names[] = {"v", "mu_uN_per_m", "FvK", "b2", "etam_Pa_s_um", "Fext_pN",
                               "D_um", "hmin_um", "hmax_um", "D0_um", "D1_um", "tc_s"};
        double x[12];
        for (int k = 0; k < 12; ++k) x[k] = parseDouble(f[3 + k], where, names[k]);
        for (int k = 0; k < 6; ++k)
            if (std::isnan(x[k])) throw InputError(fmt::format("{}: input column {} is nan", where, names[k]));
        q.p = {x[0], x[1], x[2], x[3], x[4]};
        q.fext = x[5];
        r.D = x[6], r.hmin = x[7], r.hmax = x[8], r.D0 = x[9], r.D1 = x[10], r.tc = x[11];
        r.status = f[15];
        if (r.status != "ok" && r.status != "failed")
            throw InputError(fmt::format("{}: status '{}' (valid: ok, failed)", where, r.status));
        r.reason = f[16];
        r.wallSeconds = parseDouble(f[17], where, "wall_s");
        rows.push_back(std::move(r));
    }
    if (lineNo == 0) throw InputError(fmt::format("{}: empty file (expected the header line)", path.string()));
    return rows;
}

}  // namespace trbc
